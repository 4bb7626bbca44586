#!/usr/bin/env python3
"""Write the triangle-mesh fleet: eight vehicles of different classes, each a body mesh with wheel
wells plus underside parts as separate meshes, and their vehicle files.

Run from this directory: `python3 generate_fleet.py`. Pure Python (no numpy). Writes
`fleet/<name>/*.obj` and `../<name>.toml` for every vehicle below. Everything is in the vehicle
frame (x forward, y left, z up, metres, origin on the ground under the front axle's centre), so the
vehicle files place the meshes without offsets.

The body is a height-field slab: over a grid of x and y stations the underside height z_low(x, y)
and the roof line z_top(x); side walls at y = +-width/2 and end walls at the bumpers join them.
The underside follows the centre-line profile, drops to the sill height outboard of `sill_y` between
the wheel wells, rises by `tunnel_m` along the transmission tunnel (|y| < 0.14), and rises to the
well top over each wheel well (|x - axle| < well half length, |y| > well inner edge). Stations sit
2 mm apart on both sides of each step, so steps are near-vertical walls.

Dimensions are assumptions shaped after typical vehicles of each class (none is a copy of a real
model); tyres are loaded: the vehicle file gives the static loaded radius, the free tread radius
and the sidewall bulge (hil-sim/src/world.rs, `loaded_tyre_mesh`).
"""
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


class Obj:
    def __init__(self):
        self.v = []
        self.f = []

    def vert(self, p):
        self.v.append(p)
        return len(self.v)  # 1-based

    def face(self, *idx):
        self.f.append(idx)

    def box(self, lo, hi):
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        c = [self.vert((x, y, z)) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
        # c index: z*4 + y*2 + x
        for quad in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            self.face(*(c[i] for i in quad))

    def tank(self, lo, hi, chamfer):
        """A box whose four lower edges are chamfered by `chamfer` (a fuel tank, a battery box)."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        c = chamfer
        bottom = [self.vert(p) for p in ((x0 + c, y0 + c, z0), (x1 - c, y0 + c, z0), (x1 - c, y1 - c, z0), (x0 + c, y1 - c, z0))]
        mid = [self.vert(p) for p in ((x0, y0, z0 + c), (x1, y0, z0 + c), (x1, y1, z0 + c), (x0, y1, z0 + c))]
        top = [self.vert(p) for p in ((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1))]
        self.face(*reversed(bottom))
        self.face(*top)
        for k in range(4):
            a, b = k, (k + 1) % 4
            self.face(bottom[a], bottom[b], mid[b], mid[a])
            self.face(mid[a], mid[b], top[b], top[a])

    def cylinder(self, axis, centre, radius, length, n=24, ry=None):
        """A closed cylinder (elliptic with a second radius `ry` across the first cross axis)."""
        ry = radius if ry is None else ry
        cx, cy, cz = centre
        rings = []
        for end in (-0.5, 0.5):
            ring = []
            for k in range(n):
                a = 2.0 * math.pi * k / n
                u, w = ry * math.cos(a), radius * math.sin(a)
                if axis == "x":
                    p = (cx + end * length, cy + u, cz + w)
                elif axis == "y":
                    p = (cx + u, cy + end * length, cz + w)
                else:
                    p = (cx + u, cy + w, cz + end * length)
                ring.append(self.vert(p))
            rings.append(ring)
        for k in range(n):
            a, b = k, (k + 1) % n
            self.face(rings[0][a], rings[0][b], rings[1][b], rings[1][a])
        self.face(*reversed(rings[0]))
        self.face(*rings[1])

    def prism_y(self, poly, y0, y1):
        """A convex side-view polygon [(x, z), ...] extruded from y0 to y1."""
        a = [self.vert((x, y0, z)) for x, z in poly]
        b = [self.vert((x, y1, z)) for x, z in poly]
        n = len(poly)
        for k in range(n):
            j = (k + 1) % n
            self.face(a[k], a[j], b[j], b[k])
        self.face(*reversed(a))
        self.face(*b)

    def write(self, path, comment):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w", encoding="ascii") as out:
            out.write(f"# {comment}\n# written by generate_fleet.py; vehicle frame, metres\n")
            for x, y, z in self.v:
                out.write(f"v {x:.4f} {y:.4f} {z:.4f}\n")
            for f in self.f:
                out.write("f " + " ".join(str(i) for i in f) + "\n")


def interp(poly, x):
    """Piecewise-linear interpolation of [(x, z), ...] ordered front to rear (x decreasing)."""
    if x >= poly[0][0]:
        return poly[0][1]
    for (xa, za), (xb, zb) in zip(poly, poly[1:]):
        if xb <= x <= xa:
            t = (xa - x) / (xa - xb)
            return za + t * (zb - za)
    return poly[-1][1]


def body(spec):
    wb, r, big_r = spec["wheelbase"], spec["tyre"][0], spec["tyre"][1]
    width = spec["width"] / 2.0
    tread_half = spec["tyre"][2] / 2.0
    well_in = spec["track"] / 2.0 - tread_half - spec["tyre"][4] - 0.03
    well_half = big_r + 0.05
    well_top = r + big_r + spec["arch"]
    front, rear = spec["front_x"], spec["rear_x"]
    axles = (0.0, -wb)
    eps = 0.002
    xs = set()
    n = int(round((front - rear) / 0.08))
    for k in range(n + 1):
        xs.add(round(front - k * (front - rear) / n, 4))
    for ax in axles:
        for s in (-1, 1):
            xs.add(round(ax + s * well_half, 4))
            xs.add(round(ax + s * (well_half - eps), 4))
    for x, _ in spec["profile"]:
        if rear < x < front:
            xs.add(round(x, 4))
    xs = sorted(xs, reverse=True)
    ys = {0.0, width, -width}
    for y in (well_in, well_in + eps, spec["sill_y"], spec["sill_y"] - eps, 0.14, 0.14 + eps, 0.4, 0.6):
        if 0 < y < width:
            ys.add(round(y, 4))
            ys.add(round(-y, 4))
    ys = sorted(ys)

    def z_low(x, y):
        in_well = any(abs(x - ax) < well_half - eps / 2 for ax in axles) and abs(y) > well_in + eps / 2
        if in_well:
            return well_top
        z = interp(spec["profile"], x)
        between = -wb + well_half < x < -well_half
        if between and abs(y) < 0.14 + eps / 2:
            z += spec["tunnel"]
        if between and abs(y) > spec["sill_y"] - eps / 2:
            z = spec["sill_z"]
        return z

    o = Obj()
    low = [[o.vert((x, y, z_low(x, y))) for y in ys] for x in xs]
    top = [[o.vert((x, y, interp(spec["roof"], x))) for y in (ys[0], ys[-1])] for x in xs]
    nx, ny = len(xs), len(ys)
    for i in range(nx - 1):
        for j in range(ny - 1):
            o.face(low[i][j], low[i + 1][j], low[i + 1][j + 1], low[i][j + 1])
        o.face(top[i][0], top[i][1], top[i + 1][1], top[i + 1][0])
        o.face(low[i][0], top[i][0], top[i + 1][0], low[i + 1][0])
        o.face(low[i][-1], low[i + 1][-1], top[i + 1][1], top[i][1])
    for i in (0, nx - 1):
        ring = low[i] + [top[i][1], top[i][0]]
        o.face(*ring)
    return o


def write_vehicle(spec):
    name = spec["name"]
    d = os.path.join(HERE, "fleet", name)
    body(spec).write(os.path.join(d, "body.obj"), f"{spec['title']}: body with wheel wells")
    part_lines = []
    for part in spec["parts"]:
        o = Obj()
        for kind, *args in part["shapes"]:
            getattr(o, kind)(*args)
        fname = part["name"].replace(" ", "_") + ".obj"
        o.write(os.path.join(d, fname), f"{spec['title']}: {part['name']}")
        part_lines.append(
            "\n[[parts]]\nkind = \"mesh\"\n"
            f"name = \"{part['name']}\"\n"
            f"file = \"meshes/fleet/{name}/{fname}\"\n"
            + ("rigid = false\n" if not part.get("rigid", True) else "")
        )
    r, big_r, width, rim, bulge = spec["tyre"]
    text = (
        f"# {spec['title']}.\n"
        f"# {spec['about']}\n"
        "# Written by meshes/generate_fleet.py (edit the script, not this file). Dimensions are\n"
        "# assumptions for the class, not a real model's. Format: docs/simulator.md.\n"
        f"name = \"{spec['title']}\"\n"
        f"wheelbase_m = {spec['wheelbase']}\n"
        f"track_m = {spec['track']}\n"
        f"body_width_m = {spec['width']}\n"
        f"body_height_m = {spec['height']}\n"
        f"arch_clearance_m = {spec['arch']}\n"
        "\n[tyre]            # loaded: static loaded radius, free tread radius, sidewall bulge\n"
        f"radius_m = {r}\nwidth_m = {width}\nrim_radius_m = {rim}\n"
        f"tread_radius_m = {big_r}\nsidewall_bulge_m = {bulge}\n"
        "\n[body_mesh]\n"
        f"file = \"meshes/fleet/{name}/body.obj\"\n"
        + "".join(part_lines)
    )
    with open(os.path.join(HERE, "..", f"{name}.toml"), "w", encoding="ascii") as out:
        out.write(text)


def exhaust(x_front, x_rear, y, z, r=0.025):
    return ("cylinder", "x", ((x_front + x_rear) / 2, y, z), r, x_front - x_rear, 12)


FLEET = [
    {
        "name": "city_car",
        "title": "city car",
        "about": "Small five-door hatchback, 14 in wheels; transverse rear silencer, fuel tank under the rear seat, rear mud flaps.",
        "wheelbase": 2.40, "track": 1.43, "width": 1.64, "height": 1.50, "arch": 0.04,
        "tyre": (0.276, 0.289, 0.175, 0.178, 0.012),
        "front_x": 0.72, "rear_x": -2.92,
        "profile": [(0.72, 0.30), (0.55, 0.22), (0.40, 0.195), (-0.40, 0.19), (-2.0, 0.19), (-2.62, 0.22), (-2.78, 0.27), (-2.92, 0.35)],
        "sill_y": 0.62, "sill_z": 0.18, "tunnel": 0.02,
        "roof": [(0.72, 0.75), (0.30, 0.92), (-0.30, 1.00), (-0.90, 1.50), (-2.60, 1.48), (-2.92, 1.05)],
        "parts": [
            {"name": "exhaust pipe", "shapes": [exhaust(0.10, -2.55, -0.30, 0.215)]},
            {"name": "rear silencer", "shapes": [("cylinder", "y", (-2.70, -0.12, 0.275), 0.07, 0.55, 20, 0.12)]},
            {"name": "fuel tank", "shapes": [("tank", (-2.05, -0.45, 0.205), (-1.55, 0.45, 0.40), 0.03)]},
            {"name": "front subframe", "shapes": [("box", (-0.38, -0.45, 0.20), (-0.30, 0.45, 0.25)), ("box", (-0.38, -0.45, 0.20), (0.32, -0.38, 0.25)), ("box", (-0.38, 0.38, 0.20), (0.32, 0.45, 0.25))]},
            {"name": "rear mud flaps", "rigid": False, "shapes": [("box", (-2.735, 0.62, 0.17), (-2.725, 0.79, 0.36)), ("box", (-2.735, -0.79, 0.17), (-2.725, -0.62, 0.36))]},
        ],
    },
    {
        "name": "sports_car",
        "title": "low sports car with front splitter",
        "about": "Two-door coupe on 19 in low-profile tyres; a carbon splitter 17 cm above the floor limits the approach, rear diffuser, twin exhausts.",
        "wheelbase": 2.55, "track": 1.60, "width": 1.90, "height": 1.25, "arch": 0.03,
        "tyre": (0.322, 0.335, 0.245, 0.241, 0.008),
        "front_x": 1.05, "rear_x": -3.45,
        "profile": [(1.05, 0.26), (0.85, 0.20), (0.45, 0.185), (-0.45, 0.18), (-2.10, 0.18), (-2.95, 0.22), (-3.30, 0.30), (-3.45, 0.36)],
        "sill_y": 0.70, "sill_z": 0.175, "tunnel": 0.03,
        "roof": [(1.05, 0.62), (0.40, 0.75), (-0.60, 0.85), (-1.20, 1.25), (-2.30, 1.22), (-3.45, 0.85)],
        "parts": [
            {"name": "front splitter", "shapes": [("box", (0.55, -0.78, 0.172), (1.10, 0.78, 0.182))]},
            {"name": "twin exhausts", "shapes": [exhaust(-2.90, -3.52, 0.45, 0.25, 0.045), exhaust(-2.90, -3.52, -0.45, 0.25, 0.045)]},
            {"name": "front subframe", "shapes": [("box", (-0.42, -0.50, 0.19), (-0.28, 0.50, 0.23))]},
            {"name": "rear subframe", "shapes": [("box", (-2.30, -0.50, 0.195), (-2.14, 0.50, 0.235))]},
            {"name": "diffuser fins", "shapes": [("prism_y", [(-2.95, 0.22), (-3.40, 0.33), (-3.40, 0.36), (-2.95, 0.25)], y - 0.004, y + 0.004) for y in (-0.30, 0.0, 0.30)]},
        ],
    },
    {
        "name": "pickup_bof",
        "title": "body-on-frame pickup",
        "about": "Crew-cab full-size pickup on a ladder frame; spare wheel under the bed, solid rear axle with differential, tow hitch limits the departure.",
        "wheelbase": 3.57, "track": 1.72, "width": 2.03, "height": 1.95, "arch": 0.05,
        "tyre": (0.386, 0.405, 0.275, 0.229, 0.02),
        "front_x": 0.95, "rear_x": -4.92,
        "profile": [(0.95, 0.42), (0.75, 0.37), (0.50, 0.35), (-0.50, 0.36), (-2.90, 0.42), (-3.20, 0.55), (-4.70, 0.62), (-4.92, 0.66)],
        "sill_y": 0.82, "sill_z": 0.42, "tunnel": 0.03,
        "roof": [(0.95, 1.05), (0.10, 1.15), (-0.60, 1.25), (-1.10, 1.95), (-2.50, 1.93), (-2.70, 1.40), (-4.92, 1.40)],
        "parts": [
            {"name": "frame rails", "shapes": [("box", (-2.90, -0.56, 0.34), (0.80, -0.48, 0.50)), ("box", (-2.90, 0.48, 0.34), (0.80, 0.56, 0.50)),
                                               ("box", (-4.80, -0.56, 0.44), (-2.90, -0.48, 0.58)), ("box", (-4.80, 0.48, 0.44), (-2.90, 0.56, 0.58))]},
            {"name": "crossmembers", "shapes": [("box", (x - 0.05, -0.48, 0.36), (x + 0.05, 0.48, 0.44)) for x in (-1.0, -2.2)]},
            {"name": "spare wheel", "shapes": [("cylinder", "z", (-4.35, 0.0, 0.47), 0.40, 0.27, 32)]},
            {"name": "rear differential", "shapes": [("cylinder", "y", (-3.57, 0.05, 0.386), 0.15, 0.30, 24), ("cylinder", "x", (-3.32, 0.05, 0.40), 0.09, 0.30, 16), ("cylinder", "y", (-3.57, 0.0, 0.386), 0.05, 1.40, 12)]},
            {"name": "fuel tank", "shapes": [("tank", (-2.60, -0.95, 0.33), (-1.80, -0.60, 0.55), 0.04)]},
            {"name": "tow hitch", "shapes": [("box", (-5.05, -0.035, 0.50), (-4.75, 0.035, 0.57)), ("box", (-5.15, -0.03, 0.46), (-5.02, 0.03, 0.53)), ("cylinder", "z", (-5.10, 0.0, 0.56), 0.025, 0.06, 12)]},
        ],
    },
    {
        "name": "suv_unibody",
        "title": "unibody SUV",
        "about": "Mid-size monocoque SUV; engine cradle and rear subframe, fuel tank ahead of the rear axle, exhaust with mid and rear silencers.",
        "wheelbase": 2.90, "track": 1.65, "width": 1.95, "height": 1.72, "arch": 0.05,
        "tyre": (0.355, 0.372, 0.255, 0.241, 0.015),
        "front_x": 0.95, "rear_x": -3.95,
        "profile": [(0.95, 0.38), (0.80, 0.29), (0.50, 0.25), (-0.50, 0.24), (-2.30, 0.24), (-3.30, 0.29), (-3.70, 0.36), (-3.95, 0.45)],
        "sill_y": 0.80, "sill_z": 0.23, "tunnel": 0.03,
        "roof": [(0.95, 0.90), (0.20, 1.05), (-0.40, 1.12), (-1.00, 1.72), (-3.60, 1.70), (-3.95, 1.10)],
        "parts": [
            {"name": "engine cradle", "shapes": [("box", (0.05, -0.42, 0.215), (0.55, 0.42, 0.265))]},
            {"name": "oil pan", "shapes": [("tank", (0.10, -0.30, 0.23), (0.62, 0.30, 0.32), 0.02)]},
            {"name": "fuel tank", "shapes": [("tank", (-2.55, -0.55, 0.215), (-1.85, 0.45, 0.45), 0.04)]},
            {"name": "rear subframe", "shapes": [("box", (-3.15, -0.50, 0.22), (-2.65, 0.50, 0.28))]},
            {"name": "exhaust", "shapes": [exhaust(0.0, -3.50, -0.42, 0.24, 0.03), ("cylinder", "x", (-1.35, -0.42, 0.26), 0.08, 0.50, 20)]},
            {"name": "rear silencer", "shapes": [("cylinder", "y", (-3.45, -0.25, 0.33), 0.085, 0.60, 20, 0.13)]},
        ],
    },
    {
        "name": "long_van",
        "title": "long-wheelbase van",
        "about": "Long high-roof panel van; propshaft, fuel tank, spare wheel under the rear, rear step bumper and flexible mud flaps behind the rear wheels.",
        "wheelbase": 4.33, "track": 1.72, "width": 2.02, "height": 2.70, "arch": 0.05,
        "tyre": (0.340, 0.356, 0.235, 0.203, 0.018),
        "front_x": 1.00, "rear_x": -6.28,
        "profile": [(1.00, 0.36), (0.80, 0.28), (0.50, 0.265), (-0.50, 0.255), (-3.80, 0.255), (-4.90, 0.34), (-6.00, 0.48), (-6.28, 0.55)],
        "sill_y": 0.85, "sill_z": 0.245, "tunnel": 0.02,
        "roof": [(1.00, 1.00), (0.30, 1.15), (-0.40, 2.10), (-0.80, 2.70), (-6.28, 2.70)],
        "parts": [
            {"name": "propshaft", "shapes": [("cylinder", "x", (-2.20, 0.0, 0.31), 0.04, 3.60, 12)]},
            {"name": "fuel tank", "shapes": [("tank", (-2.40, -0.95, 0.235), (-1.60, -0.40, 0.45), 0.04)]},
            {"name": "rear differential", "shapes": [("cylinder", "y", (-4.33, 0.0, 0.34), 0.13, 0.28, 24), ("cylinder", "x", (-4.12, 0.0, 0.35), 0.08, 0.25, 16)]},
            {"name": "spare wheel", "shapes": [("cylinder", "z", (-5.20, 0.0, 0.40), 0.36, 0.22, 32)]},
            {"name": "step bumper", "shapes": [("box", (-6.42, -0.60, 0.42), (-6.20, 0.60, 0.50))]},
            {"name": "rear mud flaps", "rigid": False, "shapes": [("box", (-4.735, 0.70, 0.19), (-4.725, 0.95, 0.50)), ("box", (-4.735, -0.95, 0.19), (-4.725, -0.70, 0.50))]},
        ],
    },
    {
        "name": "offroader_skid",
        "title": "off-roader with skid plates",
        "about": "Short-wheelbase off-roader on 35 in tyres, solid axles; front and transfer-case skid plates, rock sliders, rear receiver.",
        "wheelbase": 2.55, "track": 1.68, "width": 1.93, "height": 1.85, "arch": 0.06,
        "tyre": (0.425, 0.445, 0.315, 0.216, 0.02),
        "front_x": 0.80, "rear_x": -3.35,
        "profile": [(0.80, 0.62), (0.60, 0.56), (0.45, 0.52), (-0.50, 0.52), (-2.05, 0.52), (-3.00, 0.58), (-3.35, 0.62)],
        "sill_y": 0.80, "sill_z": 0.50, "tunnel": 0.02,
        "roof": [(0.80, 1.15), (0.00, 1.20), (-0.50, 1.85), (-3.35, 1.85)],
        "parts": [
            {"name": "front bumper", "shapes": [("box", (0.62, -0.80, 0.58), (0.84, 0.80, 0.74))]},
            {"name": "front skid plate", "shapes": [("prism_y", [(0.60, 0.50), (0.35, 0.38), (-0.20, 0.355), (-0.20, 0.40), (0.60, 0.54)], -0.45, 0.45)]},
            {"name": "transfer case skid", "shapes": [("box", (-1.35, -0.35, 0.30), (-0.75, 0.35, 0.34))]},
            {"name": "front axle", "shapes": [("cylinder", "y", (0.0, 0.15, 0.425), 0.15, 0.30, 24), ("cylinder", "y", (0.0, 0.0, 0.425), 0.055, 1.40, 12)]},
            {"name": "rear axle", "shapes": [("cylinder", "y", (-2.55, 0.05, 0.425), 0.15, 0.30, 24), ("cylinder", "y", (-2.55, 0.0, 0.425), 0.055, 1.40, 12)]},
            {"name": "rock sliders", "shapes": [("box", (-2.10, 0.80, 0.42), (-0.50, 0.92, 0.50)), ("box", (-2.10, -0.92, 0.42), (-0.50, -0.80, 0.50))]},
            {"name": "rear receiver", "shapes": [("box", (-3.52, -0.035, 0.50), (-3.25, 0.035, 0.57))]},
        ],
    },
    {
        "name": "minibus",
        "title": "minibus",
        "about": "Sixteen-seat minibus on a van chassis with a long rear overhang; entrance step (flexible), battery box, fuel tank, exhaust with a large silencer.",
        "wheelbase": 4.10, "track": 1.75, "width": 2.10, "height": 2.80, "arch": 0.05,
        "tyre": (0.355, 0.372, 0.225, 0.203, 0.02),
        "front_x": 1.05, "rear_x": -6.30,
        "profile": [(1.05, 0.40), (0.85, 0.30), (0.50, 0.265), (-0.50, 0.25), (-3.60, 0.25), (-4.70, 0.31), (-6.00, 0.45), (-6.30, 0.52)],
        "sill_y": 0.90, "sill_z": 0.25, "tunnel": 0.02,
        "roof": [(1.05, 1.05), (0.30, 1.20), (-0.40, 2.20), (-0.80, 2.80), (-6.30, 2.80)],
        "parts": [
            {"name": "entrance step", "rigid": False, "shapes": [("box", (-0.95, -1.08, 0.30), (-0.45, -0.88, 0.36))]},
            {"name": "battery box", "shapes": [("tank", (-2.00, 0.40, 0.235), (-1.30, 0.90, 0.50), 0.03)]},
            {"name": "fuel tank", "shapes": [("tank", (-2.00, -0.90, 0.235), (-1.20, -0.40, 0.48), 0.04)]},
            {"name": "exhaust", "shapes": [exhaust(0.20, -3.60, -0.55, 0.28, 0.03), ("cylinder", "x", (-2.80, -0.55, 0.31), 0.10, 0.80, 20)]},
            {"name": "rear differential", "shapes": [("cylinder", "y", (-4.10, 0.0, 0.355), 0.13, 0.28, 24), ("cylinder", "x", (-3.88, 0.0, 0.365), 0.08, 0.25, 16)]},
            {"name": "rear mud flaps", "rigid": False, "shapes": [("box", (-4.555, 0.72, 0.20), (-4.545, 0.98, 0.52)), ("box", (-4.555, -0.98, 0.20), (-4.545, -0.72, 0.52))]},
        ],
    },
    {
        "name": "estate_towbar",
        "title": "estate car with towbar",
        "about": "Mid-size estate on 17 in wheels with a fixed towbar (cross tube, swan neck, ball) that limits the departure; rear silencer, spare-wheel well.",
        "wheelbase": 2.83, "track": 1.58, "width": 1.85, "height": 1.50, "arch": 0.04,
        "tyre": (0.318, 0.333, 0.225, 0.216, 0.012),
        "front_x": 0.90, "rear_x": -3.93,
        "profile": [(0.90, 0.30), (0.72, 0.215), (0.45, 0.195), (-0.45, 0.19), (-2.30, 0.19), (-3.25, 0.22), (-3.70, 0.33), (-3.93, 0.40)],
        "sill_y": 0.72, "sill_z": 0.18, "tunnel": 0.025,
        "roof": [(0.90, 0.72), (0.30, 0.88), (-0.50, 0.98), (-1.10, 1.50), (-3.80, 1.45), (-3.93, 1.00)],
        "parts": [
            {"name": "towbar", "shapes": [("cylinder", "y", (-3.72, 0.0, 0.34), 0.035, 1.00, 16), ("box", (-4.05, -0.025, 0.30), (-3.72, 0.025, 0.36)), ("cylinder", "z", (-4.08, 0.0, 0.40), 0.025, 0.09, 12)]},
            {"name": "rear silencer", "shapes": [("cylinder", "y", (-3.42, -0.30, 0.27), 0.07, 0.55, 20, 0.12)]},
            {"name": "spare wheel well", "shapes": [("cylinder", "z", (-3.35, 0.0, 0.28), 0.30, 0.10, 28)]},
            {"name": "fuel tank", "shapes": [("tank", (-2.45, -0.55, 0.205), (-1.90, 0.50, 0.42), 0.04)]},
            {"name": "front subframe", "shapes": [("box", (-0.40, -0.48, 0.20), (-0.28, 0.48, 0.245))]},
            {"name": "exhaust pipe", "shapes": [exhaust(0.10, -3.20, -0.32, 0.22)]},
        ],
    },
]


if __name__ == "__main__":
    for spec in FLEET:
        write_vehicle(spec)
        print(spec["name"])
