"""A dummy node for the launcher tests (run with ``python -m launch_dummy --ros-args ...``).

Parameters: ``exit_after`` (s, < 0: never), ``exit_code``, ``stubborn`` (ignore SIGINT and SIGTERM,
so only SIGKILL ends it), ``greeting`` (a string printed at start). It prints one line with its
pid, fully qualified name, use_sim_time and greeting, then spins.
"""

import os
import signal
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException


def main() -> int:
    rclpy.init(args=sys.argv)
    node = rclpy.create_node("dummy")
    exit_after = node.declare_parameter("exit_after", -1.0).value
    code = node.declare_parameter("exit_code", 0).value
    stubborn = node.declare_parameter("stubborn", False).value
    greeting = node.declare_parameter("greeting", "").value
    if stubborn:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sim = node.get_parameter("use_sim_time").value
    print(f"up pid={os.getpid()} fqn={node.get_fully_qualified_name()} sim={sim} greeting={greeting}", flush=True)
    start = time.monotonic()
    try:
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.05)
            if 0 <= exit_after < time.monotonic() - start:
                print(f"exiting with {code}", flush=True)
                return int(code)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    print("interrupted", flush=True)  # by SIGINT: an exception, or rclpy's handler ended the context
    return 0


if __name__ == "__main__":
    sys.exit(main())
