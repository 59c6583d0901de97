#!/usr/bin/env python3
"""Example consumer of omnitrack poses in Python, over iceoryx2 shared memory (zero-copy).

Defines the C struct `PoseSample` field for field as `omnitrack::publish::PoseSample`
(docs/interfaces.md, "Pose service"), with the same iceoryx2 type name `omnitrack.PoseSample.v1`,
subscribes to the publish-subscribe service `omnitrack/pose` and prints each sample.

Set up the bindings once (PyPI package `iceoryx2`, same version as the Rust crate):

    python3 -m venv tools/.venv-iox && tools/.venv-iox/bin/pip install iceoryx2==0.10.0

Try it against the example publisher (two shells, or `&`):

    cargo run --release --example publish_poses -- 10 &
    tools/.venv-iox/bin/python tools/examples/listen_pose.py --count 10

Options: --service NAME (default omnitrack/pose), --count N (stop after N samples, default: run
until Ctrl-C), --timeout S (give up after S seconds without a sample, default 10).
"""

import argparse
import ctypes
import math
import sys
import time

import iceoryx2 as iox2


class PoseSample(ctypes.Structure):
    """`#[repr(C)]` omnitrack::publish::PoseSample: 384 bytes, alignment 8."""

    _fields_ = [
        ("timestamp_ns", ctypes.c_uint64),  # capture time of the frame
        ("sequence", ctypes.c_uint64),  # frame counter
        ("status", ctypes.c_uint8),  # 0 initializing, 1 tracking, 2 lost
        ("position_m", ctypes.c_double * 3),  # t of T_world_rig
        ("rotation_wxyz", ctypes.c_double * 4),  # R of T_world_rig
        ("covariance", ctypes.c_double * 36),  # row-major over tx,ty,tz,rx,ry,rz
        ("inliers", ctypes.c_uint32),  # accepted correspondences used
        ("xi_rad2", ctypes.c_double),  # Koch-Teller xi of the solution
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name; must equal the Rust `#[type_name(...)]`."""
        return "omnitrack.PoseSample.v1"


assert ctypes.sizeof(PoseSample) == 384 and ctypes.alignment(PoseSample) == 8
assert PoseSample.covariance.offset == 80 and PoseSample.xi_rad2.offset == 376

STATUS = {0: "initializing", 1: "tracking", 2: "lost"}


def sci(x: float) -> str:
    """Rust's `{:.3e}`: `1.500e-5`, not Python's `1.500e-05`."""
    text = f"{x:.3e}"
    if "e" not in text:  # nan, inf
        return text.upper() if text == "nan" else text
    mantissa, exponent = text.split("e")
    return f"{mantissa}e{int(exponent)}"


def line(s: PoseSample) -> str:
    """The same line format as `omnitrack listen`."""
    p, q, c = s.position_m, s.rotation_wxyz, s.covariance
    sd = [math.sqrt(max(c[i * 7], 0.0)) for i in range(6)]
    return (
        f"seq={s.sequence} t={s.timestamp_ns}ns status={STATUS.get(s.status, f'unknown({s.status})')} "
        f"pos=[{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}] q=[{q[0]:.6f},{q[1]:.6f},{q[2]:.6f},{q[3]:.6f}] "
        f"sd_m=[{sd[0]:.4f},{sd[1]:.4f},{sd[2]:.4f}] "
        f"sd_deg=[{math.degrees(sd[3]):.3f},{math.degrees(sd[4]):.3f},{math.degrees(sd[5]):.3f}] "
        f"inliers={s.inliers} xi={sci(s.xi_rad2)}"
    )


def subscribe(service_name: str):
    """The node, a subscriber to the pose service and a listener on its event service, with the
    same service settings as the Rust side (omnitrack::publish), so that either may start first."""
    # No warning about the optional iceoryx2 config file; IOX2_LOG_LEVEL still wins.
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    node.try_cleanup_dead_nodes()  # resources left by crashed processes
    name = iox2.ServiceName.new(service_name)
    service = (
        node.service_builder(name)
        .publish_subscribe(PoseSample)
        .history_size(1)
        .subscriber_max_buffer_size(8)
        .enable_safe_overflow(True)
        .max_subscribers(16)
        .max_publishers(2)
        .open_or_create()
    )
    subscriber = service.subscriber_builder().create()
    # The publisher notifies this event service after each sample: sleep on it instead of polling.
    listener = node.service_builder(name).event().open_or_create().listener_builder().create()
    # The node owns the ports: the caller keeps it alive with them.
    return node, subscriber, listener


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--service", default="omnitrack/pose")
    ap.add_argument("--count", type=int, default=None)
    ap.add_argument("--timeout", type=float, default=10.0)
    args = ap.parse_args()

    _node, subscriber, listener = subscribe(args.service)

    received = 0
    last = time.monotonic()
    while args.count is None or received < args.count:
        sample = subscriber.receive()
        if sample is None:
            if time.monotonic() - last > args.timeout:
                print(f"no sample on '{args.service}' for {args.timeout} s", file=sys.stderr)
                return 1
            listener.timed_wait(iox2.Duration.from_millis(100))
            continue
        s = sample.payload().contents
        print(line(s), flush=True)
        received += 1
        last = time.monotonic()
    return 0


if __name__ == "__main__":
    sys.exit(main())
