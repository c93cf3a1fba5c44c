#!/usr/bin/env python3
"""An independent Python reader of a running hvs.

Opens ``hvs/<instance>/decisions`` with the iceoryx2 Python bindings (PyPI ``iceoryx2==0.10.0``)
and prints the next N decisions, one line each, read from shared memory through a ctypes
structure written from docs/ipc.md (nothing of hvs is imported).

    ./target/release/hvs run &                 # the simulated robot
    pip install iceoryx2==0.10.0
    python3 shared/examples/read_decisions.py --instance default --count 5

The output has the same form as the Rust reader's (``shared/examples/read_decisions.rs``).
"""

import argparse
import ctypes
import sys
import time

import iceoryx2 as iox2


class Decision(ctypes.Structure):
    """``hvs::Decision``, 64 bytes, alignment 8 (docs/ipc.md, "decisions")."""

    _fields_ = [
        ("frame_id", ctypes.c_uint64),
        ("capture_ns", ctypes.c_uint64),
        ("published_ns", ctypes.c_uint64),
        ("command", ctypes.c_uint32),
        ("intersection", ctypes.c_uint32),
        ("wall_left", ctypes.c_float),
        ("wall_front", ctypes.c_float),
        ("wall_right", ctypes.c_float),
        ("turn_angle_deg", ctypes.c_float),
        ("ramp", ctypes.c_uint32),
        ("policy", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32 * 2),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name hvs registers the payload under."""
        return "hvs::Decision"


assert ctypes.sizeof(Decision) == 64 and ctypes.alignment(Decision) == 8

# MotionCommand and IntersectionType labels (docs/ipc.md, "Codes"); unknown codes read as
# STOP / unknown, as in hvs.
COMMANDS = {0: "STOP", 1: "FWD", 2: "LEFT", 3: "RIGHT", 4: "REV"}
INTERSECTIONS = {
    0: "unknown", 1: "dead-end", 2: "right-turn", 3: "left-turn", 4: "T-bottom",
    5: "hallway", 6: "T-wall-right", 7: "T-wall-left", 8: "B", 9: "X",
}

# The decisions topic's service settings (docs/ipc.md): an opener must ask for no more than the
# creator gave.
MAX_PUBLISHERS = 1
MAX_SUBSCRIBERS = 8
HISTORY = 1
MAX_BUFFER = 4


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--instance", default="default", help="hvs instance name")
    parser.add_argument("--count", type=int, default=5, help="decisions to print")
    parser.add_argument("--timeout-s", type=float, default=30.0,
                        help="give up after this many seconds")
    args = parser.parse_args()

    service = f"hvs/{args.instance}/decisions"
    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    try:
        port = (
            node.service_builder(iox2.ServiceName.new(service))
            .publish_subscribe(Decision)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .history_size(HISTORY)
            .subscriber_max_buffer_size(MAX_BUFFER)
            .enable_safe_overflow(True)
            .open()
        )
    except Exception as e:  # iceoryx2 raises its own exception types per failure
        print(f"cannot open {service} (is `hvs run` running with instance "
              f"{args.instance!r}?): {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    subscriber = port.subscriber_builder().create()

    deadline = time.monotonic() + args.timeout_s
    seen = 0
    while seen < args.count:
        if time.monotonic() > deadline:
            print(f"only {seen} of {args.count} decisions on {service} within "
                  f"{args.timeout_s} s", file=sys.stderr)
            return 1
        sample = subscriber.receive()
        if sample is None:
            node.wait(iox2.Duration.from_millis(5))
            continue
        d = sample.payload().contents
        print(
            f"frame {d.frame_id} command {COMMANDS.get(d.command, 'STOP')} "
            f"intersection {INTERSECTIONS.get(d.intersection, 'unknown')} "
            f"walls L {d.wall_left:.2f} F {d.wall_front:.2f} R {d.wall_right:.2f} "
            f"policy {d.policy}",
            flush=True,
        )
        seen += 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
