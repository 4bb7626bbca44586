"""Throughput of velodyne-decoder (PyPI) on a pcap: the peer in bench/vlp16_vs_peer.sh.

usage: python3 bench/peer_velodyne_decoder.py FILE.pcap [SECONDS]

Decodes the whole file with velodyne_decoder.read_pcap (pcap parsing + decoding to x/y/z, model
VLP16, min range 0.1 m) repeatedly for about SECONDS and prints the best pass and the median as
`peer points=N seconds=S points_per_s=P median_points_per_s=M version=V`.
"""
import sys
import time

import velodyne_decoder as vd


def one_pass(path, config):
    return sum(len(points) for _, points in vd.read_pcap(path, config))


def main():
    path = sys.argv[1]
    budget = float(sys.argv[2]) if len(sys.argv) > 2 else 3.0
    config = vd.Config(model=vd.Model.VLP16, min_range=0.1)
    points = one_pass(path, config)  # warm-up
    times = []
    start = time.perf_counter()
    while len(times) < 5 or time.perf_counter() - start < budget:
        t = time.perf_counter()
        n = one_pass(path, config)
        times.append(time.perf_counter() - t)
        if n != points:
            sys.exit(f"pass decoded {n} points, the first {points}")
    times.sort()
    best, median = times[0], times[len(times) // 2]
    version = getattr(vd, "__version__", "unknown")
    print(
        f"peer points={points} seconds={best:.6f} points_per_s={points / best:.0f} "
        f"median_points_per_s={points / median:.0f} version={version}"
    )


if __name__ == "__main__":
    main()
