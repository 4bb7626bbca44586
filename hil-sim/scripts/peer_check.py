"""Independent check of passangle-sim's VLP-16 packets with a third-party decoder.

usage: python3 hil-sim/scripts/peer_check.py [PASSANGLE_SIM_BINARY]

Simulates one second of a noiseless, dropout-free VLP-16 parked under the SUV of
hil-sim/vehicles/suv.toml at mid-wheelbase (optical centre 0.12 m above the ground, floor 0.249 m
above the ground there), writes a pcap, decodes it with velodyne-decoder (PyPI, C++ core of the ROS
driver) and checks that the peer sees the ground at z = -0.120 m and the floor at 0.129-0.142 m in
the sensor frame, and one point per simulated return. Exits non-zero on a mismatch.
"""
import os
import subprocess
import sys
import tempfile

import numpy as np
import velodyne_decoder as vd

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    binary = sys.argv[1] if len(sys.argv) > 1 else "target/release/passangle-sim"
    with tempfile.TemporaryDirectory() as tmp:
        scenario = os.path.join(tmp, "still.toml")
        with open(scenario, "w") as f:
            f.write(
                f'vehicle = "{os.path.join(HERE, "..", "vehicles", "suv.toml")}"\n'
                "seed = 11\nduration_s = 1.0\n"
                "[robot]\nstart_x_m = -1.445\nspeed_mps = 0.001\ndistance_m = 0.001\n"
                "[lidar]\nrange_noise_sigma_m = 0.0\ndropout_probability = 0.0\nmin_range_m = 0.1\n"
            )
        pcap = os.path.join(tmp, "still.pcap")
        subprocess.run([binary, "lidar", scenario, "--pcap", pcap], check=True)
        config = vd.Config(model=vd.Model.VLP16, min_range=0.1)
        points = np.concatenate([p for _, p in vd.read_pcap(pcap, config)])
        returns = count_returns(pcap)
    z = points[:, 2]
    ground = np.median(z[z < -0.05])
    floor = np.median(z[z > 0.05])
    print(f"peer points {len(points)}, simulated returns {returns}")
    print(f"ground z median {ground:.4f} m (expect -0.1200), floor z median {floor:.4f} m (expect 0.129..0.142)")
    ok = len(points) == returns and abs(ground + 0.12) < 0.001 and 0.128 < floor < 0.143
    print("OK" if ok else "MISMATCH")
    sys.exit(0 if ok else 1)


def count_returns(pcap):
    """Non-zero distances in the data packets (UDP payloads of 1206 bytes) of a classic pcap."""
    data = open(pcap, "rb").read()
    offset, count = 24, 0
    while offset + 16 <= len(data):
        incl = int.from_bytes(data[offset + 8 : offset + 12], "little")
        frame = data[offset + 16 : offset + 16 + incl]
        offset += 16 + incl
        payload = frame[42:]
        if len(payload) != 1206:
            continue
        for block in range(12):
            for channel in range(32):
                o = block * 100 + 4 + channel * 3
                if payload[o] or payload[o + 1]:
                    count += 1
    return count


if __name__ == "__main__":
    main()
