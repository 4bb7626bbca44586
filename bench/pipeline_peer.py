"""KISS-ICP (PyPI `kiss-icp`) on the runs exported by `bench_pipeline --export`: the peer in
bench/pipeline_peer.sh.

usage:
  python3 bench/pipeline_peer.py run RUN_DIR [--max-range-m R] [--min-range-m R]
      KISS-ICP on RUN_DIR/frames, its error and time per frame, our error recomputed from
      RUN_DIR/ours-*.txt, and a truth check of the frame conventions; prints one JSON line.
  python3 bench/pipeline_peer.py table RESULTS.jsonl
      The markdown table of the `run` lines.

Export layout (hil-sim/examples/bench_pipeline.rs, `export_frames`): frames/NNNNNN.bin holds per
point x y z t as f32 (sensor frame of the VLP-16, t = firing time after the frame start, s);
truth.txt per frame `start_s end_s` and the true vehicle_from_robot at both instants (KITTI rows);
robot_from_lidar.txt the mount; ours-SLUG.txt our world_from_robot per frame (at start_s);
ours.tsv the bench's own figures per variant.

Error definitions, the same as the bench's `evaluate`: both trajectories are taken relative to
their first frame; ATE = RMS over frames of the robot's translation error, metres; drift = the
last frame's translation error / the straight distance from the first to the last frame. Every
pose is compared with the truth at the instant it stands for: ours at the frame start, KISS-ICP
at the frame end (it deskews each frame to its last point). KISS-ICP estimates the sensor's
pose; it is moved to the robot frame through the mount, robot0_from_robot = M lidar0_from_lidar
M^-1 with M = robot_from_lidar, before the comparison.

Timing: wall time and this thread's CPU time (time.thread_time) of `KissICP.register_frame`
per frame (preprocessing, deskew, voxelisation, ICP, map update), frames loaded beforehand;
KISS-ICP limited to one thread (its TBB pool runs in the calling thread); the caller pins the
process to one core. The bench measures ours the same two ways; the ratio in the table is of
CPU times, which the other load on a shared machine does not inflate.
"""

import glob
import json
import os
import sys
import time

import numpy as np

import kiss_icp
from kiss_icp.config import KISSConfig
from kiss_icp.kiss_icp import KissICP


def kitti_pose(numbers):
    """4x4 matrix from the 12 numbers of a KITTI row."""
    pose = np.eye(4)
    pose[:3, :] = np.asarray(numbers, dtype=float).reshape(3, 4)
    return pose


def read_rows(path):
    """Numeric rows of a text file, '#' lines skipped; the error names the file and line."""
    rows = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            if line.startswith("#") or not line.strip():
                continue
            try:
                rows.append([float(v) for v in line.split()])
            except ValueError as e:
                sys.exit(f"{path}:{number}: not a row of numbers: {e}")
    return rows


def load_run(run_dir):
    truth = read_rows(os.path.join(run_dir, "truth.txt"))
    for number, row in enumerate(truth, 1):
        if len(row) != 26:
            sys.exit(f"{run_dir}/truth.txt: data row {number} has {len(row)} numbers, expected 26")
    mount = read_rows(os.path.join(run_dir, "robot_from_lidar.txt"))
    if len(mount) != 1 or len(mount[0]) != 12:
        sys.exit(f"{run_dir}/robot_from_lidar.txt: expected one row of 12 numbers")
    frames = sorted(glob.glob(os.path.join(run_dir, "frames", "*.bin")))
    if len(frames) != len(truth):
        sys.exit(f"{run_dir}: {len(frames)} frames but {len(truth)} truth rows")
    return {
        "start_s": np.array([r[0] for r in truth]),
        "end_s": np.array([r[1] for r in truth]),
        "truth_start": [kitti_pose(r[2:14]) for r in truth],
        "truth_end": [kitti_pose(r[14:26]) for r in truth],
        "robot_from_lidar": kitti_pose(mount[0]),
        "frames": frames,
    }


def read_frame(path):
    """Points (n x 3, float64) and firing times after the frame start (n, seconds)."""
    raw = np.fromfile(path, dtype="<f4")
    if raw.size % 4:
        sys.exit(f"{path}: {raw.size * 4} bytes is not a whole number of 16-byte points")
    raw = raw.reshape(-1, 4)
    return raw[:, :3].astype(np.float64), raw[:, 3].astype(np.float64)


def trajectory_error(estimate, truth):
    """ATE (m) and drift (per metre) of `estimate` against `truth`, both lists of 4x4
    robot poses, each taken relative to its own first pose (the bench's definitions)."""
    e0 = np.linalg.inv(estimate[0])
    t0 = np.linalg.inv(truth[0])
    errors = np.array(
        [np.linalg.norm((e0 @ e)[:3, 3] - (t0 @ t)[:3, 3]) for e, t in zip(estimate, truth)]
    )
    travelled = np.linalg.norm((t0 @ truth[-1])[:3, 3])
    return float(np.sqrt(np.mean(errors**2))), float(errors[-1] / max(travelled, 1e-9))


def kiss_config(max_range_m, min_range_m):
    """KISS-ICP's defaults but for the range limits and one thread. The voxel size follows
    KISS-ICP's own rule for an unset voxel size (max_range / 100, kiss_icp.config.load_config)."""
    config = KISSConfig()
    config.data.max_range = max_range_m
    config.data.min_range = min_range_m
    config.data.deskew = True
    config.mapping.voxel_size = max_range_m / 100.0
    config.registration.max_num_threads = 1
    return config


def run_kiss(run, config, ground_cut_z_m=None):
    """Lidar poses (lidar0_from_lidar at each frame's end) and per frame (wall s, CPU s). With
    `ground_cut_z_m`, points below that height in the sensor frame are dropped before KISS-ICP
    sees them (the cut is not timed)."""
    odometry = KissICP(config)
    frames = [read_frame(path) for path in run["frames"]]
    if ground_cut_z_m is not None:
        frames = [(p[p[:, 2] > ground_cut_z_m], t[p[:, 2] > ground_cut_z_m]) for p, t in frames]
    poses, seconds = [], []
    for points, times in frames:
        start, cpu_start = time.perf_counter(), time.thread_time()
        odometry.register_frame(points, times)
        seconds.append((time.perf_counter() - start, time.thread_time() - cpu_start))
        poses.append(odometry.last_pose.copy())
    return poses, np.array(seconds)


def to_robot(lidar_poses, robot_from_lidar):
    lidar_from_robot = np.linalg.inv(robot_from_lidar)
    return [robot_from_lidar @ p @ lidar_from_robot for p in lidar_poses]


def log_so3(rotation):
    """Rotation vector of a rotation matrix (angles well below pi)."""
    angle = np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1.0, 1.0))
    axis = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    return axis / 2 if angle < 1e-9 else axis * angle / (2 * np.sin(angle))


def exp_so3(vectors):
    """Rotation matrices (n x 3 x 3) of rotation vectors (n x 3), Rodrigues."""
    angle = np.linalg.norm(vectors, axis=1)[:, None, None]
    k = np.zeros((len(vectors), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -vectors[:, 2], vectors[:, 1], -vectors[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = vectors[:, 2], -vectors[:, 1], vectors[:, 0]
    small = angle < 1e-12
    a = np.where(small, 1.0, np.sin(angle) / np.where(small, 1.0, angle))
    b = np.where(small, 0.5, (1 - np.cos(angle)) / np.where(small, 1.0, angle**2))
    return np.eye(3) + a * k + b * (k @ k)


def in_vehicle(run, index, mount):
    """Frame `index`'s points moved into the vehicle frame by the true pose at each point's firing
    time, from the exported files alone. Approximate: the pose is interpolated between the
    frame's start and end (translation linearly, rotation along the geodesic); the simulated
    vibration is not linear within a sweep, so far points mid-sweep land up to about 15 mm
    (0.13 degrees at 6.5 m) from where the exact truth puts them; the median is sub-millimetre."""
    points, times = read_frame(run["frames"][index])
    start, end = run["truth_start"][index], run["truth_end"][index]
    span = max(run["end_s"][index] - run["start_s"][index], 1e-9)
    s = (times / span)[:, None]
    rotations = start[:3, :3] @ exp_so3(s * log_so3(start[:3, :3].T @ end[:3, :3]))
    translations = (1 - s) * start[:3, 3] + s * end[:3, 3]
    in_robot = points @ mount[:3, :3].T + mount[:3, 3]
    return np.einsum("nij,nj->ni", rotations, in_robot) + translations


def convention_check(run_dir, run, mount):
    """Median distance (m) between the sample points of check.txt (placed by the bench with the
    exact truth, and shown there to lie on the true surfaces) and the same points placed from
    the exported frames, truth and `mount` as this script reads them: below a millimetre if this
    script reads the frames, poses and mount as the bench wrote them (see `in_vehicle` for why
    not the maximum)."""
    rows = read_rows(os.path.join(run_dir, "check.txt"))
    distances, cache = [], {}
    for frame, point, x, y, z in rows:
        frame = int(frame)
        if frame not in cache:
            cache[frame] = in_vehicle(run, frame, mount)
        distances.append(float(np.linalg.norm(cache[frame][int(point)] - [x, y, z])))
    return float(np.median(distances))


def ours(run_dir, truth_start):
    """Our variants: error recomputed from the exported trajectory, checked against the bench."""
    results = {}
    for row in open(os.path.join(run_dir, "ours.tsv")):
        if row.startswith("#"):
            continue
        variant, slug, ate, drift, ms, cpu_ms, frames = row.rstrip("\n").split("\t")
        rows = read_rows(os.path.join(run_dir, f"ours-{slug}.txt"))
        if len(rows) != len(truth_start):
            sys.exit(f"{run_dir}/ours-{slug}.txt: {len(rows)} poses, {len(truth_start)} frames")
        poses = [kitti_pose(r[1:13]) for r in rows]
        my_ate, my_drift = trajectory_error(poses, truth_start)
        # The same definition from the same poses must give the bench's figures.
        if abs(my_ate - float(ate)) > 1e-6 or abs(my_drift - float(drift)) > 1e-6:
            sys.exit(
                f"{run_dir}: {variant}: recomputed ATE {my_ate:.6f} m / drift {my_drift:.6f}, "
                f"the bench printed {float(ate):.6f} / {float(drift):.6f}: definitions differ"
            )
        results[variant] = {
            "ate_m": my_ate,
            "drift_per_m": my_drift,
            "ms_per_frame": float(ms),
            "cpu_ms_per_frame": float(cpu_ms),
        }
    return results


def command_run(args):
    run_dir = args[0]
    max_range_m = float(args[args.index("--max-range-m") + 1]) if "--max-range-m" in args else 12.0
    min_range_m = float(args[args.index("--min-range-m") + 1]) if "--min-range-m" in args else 0.4
    run = load_run(run_dir)
    mount = run["robot_from_lidar"]
    config = kiss_config(max_range_m, min_range_m)
    lidar_poses, seconds = run_kiss(run, config)
    ate, drift = trajectory_error(to_robot(lidar_poses, mount), run["truth_end"])
    # Diagnostic: the ground cut away 4 cm above the ground under the sensor (its height is the
    # mount's z), the job our ground removal does; not part of KISS-ICP's defaults.
    cut_z_m = -mount[2, 3] + 0.04
    cut_poses, cut_seconds = run_kiss(run, config, cut_z_m)
    cut_ate, cut_drift = trajectory_error(to_robot(cut_poses, mount), run["truth_end"])
    check = convention_check(run_dir, run, mount)
    # Negative control: the same check with the robot's motion taken as the sensor's.
    check_wrong = convention_check(run_dir, run, np.eye(4))
    if check > 0.003:
        sys.exit(f"{run_dir}: frame convention check failed: points land {check:.4f} m off")
    result = {
        "run": os.path.basename(os.path.normpath(run_dir)),
        "frames": len(seconds),
        "kiss": {
            "ate_m": ate,
            "drift_per_m": drift,
            "ms_per_frame": 1e3 * float(np.mean(seconds[:, 0])),
            "cpu_ms_per_frame": 1e3 * float(np.mean(seconds[:, 1])),
            "version": kiss_icp.__version__,
            "max_range_m": max_range_m,
            "min_range_m": min_range_m,
            "voxel_m": config.mapping.voxel_size,
        },
        "kiss_ground_cut": {
            "ate_m": cut_ate,
            "drift_per_m": cut_drift,
            "ms_per_frame": 1e3 * float(np.mean(cut_seconds[:, 0])),
            "cpu_ms_per_frame": 1e3 * float(np.mean(cut_seconds[:, 1])),
            "cut_z_in_lidar_m": cut_z_m,
        },
        "ours": ours(run_dir, run["truth_start"]),
        "convention_check_m": check,
        "convention_check_identity_mount_m": check_wrong,
    }
    print(json.dumps(result))


def command_table(args):
    results = [json.loads(line) for line in open(args[0]) if line.strip()]
    if not results:
        sys.exit(f"{args[0]}: no results")
    print(
        "| run | frames | method | ATE m | drift %/m | wall ms/frame | CPU ms/frame "
        "| CPU time / ours laser+wheel |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        reference_ms = r["ours"]["laser+wheel"]["cpu_ms_per_frame"]
        rows = [
            ("KISS-ICP (defaults, max range 12 m)", r["kiss"]),
            ("KISS-ICP, ground cut (diagnostic)", r["kiss_ground_cut"]),
            ("ours, laser only", r["ours"]["laser only"]),
            ("ours, laser + wheel", r["ours"]["laser+wheel"]),
        ]
        for method, f in rows:
            print(
                f"| {r['run']} | {r['frames']} | {method} | {f['ate_m']:.4f} "
                f"| {100 * f['drift_per_m']:.2f} | {f['ms_per_frame']:.1f} "
                f"| {f['cpu_ms_per_frame']:.1f} | {f['cpu_ms_per_frame'] / reference_ms:.2f} |"
            )
    k = results[0]["kiss"]
    print()
    print(
        f"KISS-ICP {k['version']}: defaults except max_range {k['max_range_m']} m, min_range "
        f"{k['min_range_m']} m, voxel {k['voxel_m']} m (max_range / 100, its own rule), one "
        "thread, deskew on with per-point times. Ground cut: points below "
        f"{results[0]['kiss_ground_cut']['cut_z_in_lidar_m']:.2f} m in the sensor frame dropped "
        "(4 cm above the ground), the rest as the defaults row."
    )
    checks = ", ".join(
        f"{r['run']} {1e3 * r['convention_check_m']:.1f} mm "
        f"(identity mount {1e3 * r['convention_check_identity_mount_m']:.0f} mm)"
        for r in results
    )
    print(
        "Frame-convention check (median distance between sample points placed by the bench with "
        f"the exact truth and by this script from the exported files): {checks}"
    )


def main():
    if len(sys.argv) < 3 or sys.argv[1] not in ("run", "table"):
        sys.exit(__doc__)
    if sys.argv[1] == "run":
        command_run(sys.argv[2:])
    else:
        command_table(sys.argv[2:])


if __name__ == "__main__":
    main()
