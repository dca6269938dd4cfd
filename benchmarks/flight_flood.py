"""A detection flood during a dry run: ``hptrack vehicle-sim`` and ``hptrack fly`` on loopback (the
paper-flight example, the default ``mcts``), and a sender that floods ``fly``'s detection port
once offboard has started. It prints what ``fly`` itself sent (its setpoints, their rate, the
largest gap), the telemetry's gaps, how the mission ended, and the detection lines received,
logged and dropped (from the mission log).

    python3 benchmarks/flight_flood.py      # 175,000 lines in 20 s of a 60 s flight
    python3 benchmarks/flight_flood.py --budget 15 --flood-s 5 --workdir /tmp/flood

The end-to-end tests (``tests/runtime/test_flight_integration.py``) start their dry runs and
floods with the functions here.
"""

from __future__ import annotations

import argparse
import json
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from hptrack.runtime.log import read_log

SCENARIO = Path(__file__).resolve().parents[1] / "examples/paper-flight.yaml"
CLI = [sys.executable, "-m", "hptrack"]


def free_udp_port() -> int:
    """A UDP port on loopback that nothing uses now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_dry_run(
    workdir: Path, example: Path, budget: float, stub_args=(), env: dict | None = None
) -> dict:
    """A copy of ``example`` with ``budget`` (s) in ``workdir``, free ports, and the vehicle
    stub running (with ``env`` as its environment, default this one's); returns the scenario,
    the ``fly`` command (without ``--log``), the stub's process, its statistics file, the log
    path and the detection port."""
    data = yaml.safe_load(example.read_text())
    data["budget"] = budget
    scenario = workdir / "flight.yaml"
    scenario.write_text(yaml.safe_dump(data))
    mav, det = free_udp_port(), free_udp_port()
    stats = workdir / "vehicle.json"
    stub = subprocess.Popen(
        [
            *CLI,
            "vehicle-sim",
            str(scenario),
            "--mavlink",
            f"udpout://127.0.0.1:{mav}",
            "--detections",
            f"udp://127.0.0.1:{det}",
            "--duration",
            str(budget + 150),
            "--stats",
            str(stats),
            *stub_args,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    fly = [
        *CLI,
        "fly",
        str(scenario),
        "--connection",
        f"udpin://127.0.0.1:{mav}",
        "--detections",
        f"udp://127.0.0.1:{det}",
        "--altitude",
        "5",
        "--takeoff",
        "--no-live",
        "--connect-timeout",
        "20",
    ]
    return {
        "scenario": scenario,
        "fly": fly,
        "stub": stub,
        "stats": stats,
        "log": workdir / "flight.jsonl",
        "detections_port": det,
    }


def wait_for_offboard(path: Path, timeout_s: float = 90.0) -> None:
    """Wait until the mission log at ``path`` says offboard started."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists() and "offboard started" in path.read_text():
            return
        time.sleep(0.1)
    raise AssertionError("offboard never started")


def end_process(process: subprocess.Popen) -> None:
    """Stop ``process`` (Ctrl-C) if it runs and close its pipes."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()


def flood(
    port: int,
    duration_s: float,
    malformed_per_s: int = 2000,
    plausible_per_s: int = 1000,
    big_per_s: int = 5,
    huge_at_s: float | None = None,
) -> int:
    """Send detection lines to ``port`` on loopback for ``duration_s``: malformed lines in
    datagrams of 5, plausible detections of ``p1`` one per datagram, ``big_per_s`` datagrams of
    1,000 plausible lines per second, and (at ``huge_at_s``) one datagram of 1,700 malformed
    lines; returns the lines sent."""
    plausible = [
        json.dumps({"id": "p1", "x": 30.0 + 0.01 * i, "y": 10.0}).encode() for i in range(50)
    ]
    malformed = b"\n".join([b'{"id": "p1", "x": oops}', b"garbage", b"[1, 2", b"{}", b"null"])
    big = b"\n".join(plausible[i % 50] for i in range(1000))
    huge = b"\n".join(b"not json at all %d" % i for i in range(1700))
    step_s, sent, owed = 0.01, 0, [0.0, 0.0, 0.0]
    rounds = round(duration_s / step_s)
    huge_round = None if huge_at_s is None else round(huge_at_s / step_s)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        address = ("127.0.0.1", port)
        start = time.monotonic()
        for k in range(rounds):
            owed = [
                owed[0] + malformed_per_s / 5 * step_s,
                owed[1] + plausible_per_s * step_s,
                owed[2] + big_per_s * step_s,
            ]
            while owed[0] >= 1:
                sender.sendto(malformed, address)
                sent, owed[0] = sent + 5, owed[0] - 1
            while owed[1] >= 1:
                sender.sendto(plausible[sent % 50], address)
                sent, owed[1] = sent + 1, owed[1] - 1
            while owed[2] >= 1:
                sender.sendto(big, address)
                sent, owed[2] = sent + 1000, owed[2] - 1
            if k == huge_round:
                sender.sendto(huge, address)
                sent += 1700
            time.sleep(max(0.0, start + (k + 1) * step_s - time.monotonic()))
    return sent


def figures(log_path: Path) -> dict:
    """What the mission log says of a flight: ``fly``'s own setpoints (count, mission time,
    rate, largest gap), the telemetry's gaps, the end, and the detection lines' counts."""
    records = read_log(log_path).records
    setpoints = next(r for r in records if r["kind"] == "status" and "setpoints" in r)
    lines = next(r for r in records if r["kind"] == "status" and "detection_lines" in r)
    end = next(r for r in records if r["kind"] == "end")
    odometry = [r["t"] for r in records if r["kind"] == "odometry" and r["accepted"]]
    gaps = [b - a for a, b in zip(odometry, odometry[1:], strict=False)]
    return {
        "setpoints": setpoints["setpoints"],
        "mission_time_s": setpoints["mission_time_s"],
        "setpoint_rate_hz": setpoints["setpoints"] / setpoints["mission_time_s"],
        "max_setpoint_gap_s": setpoints["max_gap_s"],
        "telemetry_gaps_over_0.5_s": sum(g > 0.5 for g in gaps),
        "max_telemetry_gap_s": max(gaps),
        "ended_by": end["reason"],
        "end_time_s": end["time"],
        "end_t_s": end["t"],
        "detection_lines": lines["detection_lines"],
        "detection_records": sum(r["kind"] == "detection" for r in records),
        "log_bytes": log_path.stat().st_size,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--budget", type=float, default=60.0, help="mission budget, s")
    parser.add_argument("--flood-s", type=float, default=20.0, help="length of the flood, s")
    parser.add_argument("--after-s", type=float, default=5.0, help="flood after offboard, s")
    parser.add_argument("--malformed", type=int, default=2500, help="malformed lines per s")
    parser.add_argument("--plausible", type=int, default=1250, help="plausible lines per s")
    parser.add_argument("--big", type=int, default=5, help="datagrams of 1,000 lines per s")
    parser.add_argument("--workdir", type=Path, default=None, help="keep the files here")
    parser.add_argument("fly_args", nargs="*", help="more options for fly (after --)")
    args = parser.parse_args()
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="flight-flood-"))
    workdir.mkdir(parents=True, exist_ok=True)
    run = start_dry_run(workdir, SCENARIO, args.budget)
    try:
        fly = subprocess.Popen(
            [*run["fly"], "--log", str(run["log"]), *args.fly_args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        wait_for_offboard(run["log"], 600.0)
        time.sleep(args.after_s)
        sent = flood(run["detections_port"], args.flood_s, args.malformed, args.plausible, args.big)
        out, err = fly.communicate(timeout=args.budget + 300)
    finally:
        end_process(run["stub"])
    result = {"fly_exit_code": fly.returncode, "lines_sent": sent, **figures(run["log"])}
    print(json.dumps(result, indent=1))
    print(out + err)


if __name__ == "__main__":
    main()
