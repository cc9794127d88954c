"""Measure the links against the fake devices: ``python -m hil_sim.devices.measure``.

For each transport it starts ``fdi sim serve`` as a separate process, reads through the
daemon's link for ``--seconds`` and reports samples/s, seq gaps and the link latency: the
time from a sample's due time on the device (its ``tick0_monotonic_s`` + seq / fs, on the
machine-wide monotonic clock) to its delivery by ``Link.read``. For Modbus it also reports
back-to-back polls/s; it ends with the serial decoder's throughput. ``--json FILE`` writes
the figures.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np

from fdi_daemon.io.links.base import make_link
from fdi_daemon.io.serial_frames import Frame, FrameDecoder, encode_frame

TRANSPORTS = {
    "modbus-tcp": ["--modbus-tcp", "127.0.0.1:0"],
    "modbus-rtu": ["--modbus-rtu"],
    "serial": ["--serial"],
}


def measure_transport(kind: str, seconds: float) -> dict:
    proc = subprocess.Popen(
        [sys.executable, "-m", "fdi_daemon", "sim", "serve", *TRANSPORTS[kind]],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        where = proc.stdout.readline().strip()
        proc.stdin.write('{"status": true}\n')
        proc.stdin.flush()
        status = json.loads(proc.stdout.readline())["status"]
        if kind == "modbus-tcp":
            host, port = where.rsplit(":", 1)
            config = {"kind": kind, "host": host, "port": int(port)}
        else:
            config = {"kind": kind, "port": where}
        link = make_link(config)
        link.open()
        out: dict = {}
        if kind != "serial":
            start, polls = time.monotonic(), 0
            while time.monotonic() - start < min(2.0, seconds):
                link.poll()
                polls += 1
            out["back_to_back_polls_per_s"] = polls / (time.monotonic() - start)
        seqs, latency = [], []
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            for s in link.read(0.05):
                seqs.append(s.seq)
                latency.append(
                    time.monotonic() - status["tick0_monotonic_s"] - s.seq / status["fs_hz"]
                )
        elapsed = time.monotonic() - start
        link.close()
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    lat_ms = np.array(latency[len(latency) // 10 :]) * 1e3  # skip the connection's start
    return {
        **out,
        "samples_per_s": len(seqs) / elapsed,
        "seq_gaps": int(np.count_nonzero(np.diff(seqs) != 1)),
        "latency_ms": {
            "p50": float(np.percentile(lat_ms, 50)),
            "p99": float(np.percentile(lat_ms, 99)),
            "max": float(lat_ms.max()),
        },
        "counters": link.counters(),
    }


def decoder_frames_per_s(frames: int = 100_000, chunk_bytes: int = 64) -> float:
    wire = b"".join(encode_frame(Frame(i, 0.1, -0.2, 0.001)) for i in range(frames))
    decoder = FrameDecoder()
    start = time.perf_counter()
    decoded = sum(
        len(decoder.feed(wire[i : i + chunk_bytes])) for i in range(0, len(wire), chunk_bytes)
    )
    return decoded / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="reading time per link")
    parser.add_argument(
        "--decoder-frames", type=int, default=100_000, help="frames for the decoder throughput"
    )
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON")
    args = parser.parse_args(argv)
    results = {kind: measure_transport(kind, args.seconds) for kind in TRANSPORTS}
    results["serial_decoder_frames_per_s"] = decoder_frames_per_s(args.decoder_frames)
    for kind in TRANSPORTS:
        r = results[kind]
        polls = (
            f", back-to-back {r['back_to_back_polls_per_s']:.0f} polls/s"
            if "back_to_back_polls_per_s" in r
            else ""
        )
        print(
            f"{kind:11s} {r['samples_per_s']:6.1f} samples/s, {r['seq_gaps']} gaps, latency "
            f"p50 {r['latency_ms']['p50']:.1f} ms p99 {r['latency_ms']['p99']:.1f} ms "
            f"max {r['latency_ms']['max']:.1f} ms{polls}"
        )
    print(f"serial decoder {results['serial_decoder_frames_per_s']:,.0f} frames/s (64-byte reads)")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
