"""``mrslam launch CONFIG.yaml``: start the nodes a config lists, each in its own process.

ROS 2's launch system is not on PyPI; this is the project's own. Every node runs as::

    python -m <module> [args...] --ros-args -r __node:=<name> [-r __ns:=/<namespace>]
        [-r from:=to ...] [--params-file <file given in the config>] --params-file <generated>

The generated params file holds the node's ``params`` (nested keys become the dotted parameter
names of the core's config dataclasses) and ``use_sim_time``; it applies to the node whatever its
name (``/**``). Processes get the environment of :func:`mrslam_ros.env.node_env` (generated
interfaces on the paths) plus ``env``. Each output line is written to the launcher's log prefixed
with ``[namespace/name]`` and, with ``log_dir``, to ``<log_dir>/<namespace>_<name>.log`` as is.

Stopping: Ctrl-C (SIGINT) or SIGTERM to the launcher, or a ``required`` node exiting, stops all
nodes: SIGINT to each node's process group, then SIGTERM, then SIGKILL, waiting ``stop_timeout``
seconds after each. The exit status is 0 after Ctrl-C or SIGTERM, or when the node(s) whose exit
ended the launch exited with 0; 1 when one of them failed; 2 for a bad config.

Config (YAML, :class:`LaunchConfig`)::

    use_sim_time: true
    log_dir: runs/launch_logs          # optional, relative to the config file
    nodes:
      - {module: mrslam_ros.sim_node, name: sim, params: {robots: 2, sim: {world: small}}}
      - module: mrslam_ros.frontend_node
        name: frontend
        namespace: robot1
        params: {robot: robot1}
        params_files: [frontend.yaml]  # ROS params-file format, relative to the config file
        remap: {observations: obs}
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import yaml

from mrslam_core.configio import ConfigError, load_yaml


@dataclass(frozen=True)
class NodeSpec:
    """One node process.

    Attributes:
        module: Python module run with ``python -m`` (e.g. ``mrslam_ros.slam_node``).
        name: node name (``__node`` remap); also the log prefix.
        namespace: ROS namespace without leading slash (e.g. ``robot1``); empty for the root.
        params: parameters as a nested mapping (keys of the node's config dataclass).
        params_files: further ``--params-file`` YAML files (ROS format), applied before ``params``.
        remap: topic remappings ``{from: to}``.
        args: extra command-line arguments before ``--ros-args``.
        env: extra environment variables.
        required: when this node exits, every other node is stopped.
        prefix: command words put before the node's interpreter, e.g. ``[ip, netns, exec, robots]``
            to run it in another network namespace (another "host"), or ``[taskset, -c, 1]``.
        use_sim_time: this node's ``use_sim_time``, overriding the config's (None: the config's).
            The node that publishes /clock (the simulator) must run on wall time: its timers
            would otherwise wait for a /clock that only they would publish.
    """

    module: str
    name: str
    namespace: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    params_files: list[str] = field(default_factory=list)
    remap: dict[str, str] = field(default_factory=dict)
    args: list[str] = field(default_factory=list)
    env: dict[str, str] = field(default_factory=dict)
    required: bool = True
    use_sim_time: bool | None = None
    prefix: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.module or not self.name or "/" in self.name:
            raise ValueError(f"a node needs a module and a name without '/' (got {self.module!r}, {self.name!r})")

    @property
    def label(self) -> str:
        """``namespace/name`` (or ``name``)."""
        ns = self.namespace.strip("/")
        return f"{ns}/{self.name}" if ns else self.name


@dataclass(frozen=True)
class LaunchConfig:
    """The nodes to start and how.

    Attributes:
        nodes: the node processes.
        use_sim_time: set the ``use_sim_time`` parameter of every node (time from /clock).
        log_dir: folder for one log file per node (None: only the prefixed combined output).
        stop_timeout: seconds to wait after each of SIGINT, SIGTERM before the next signal [s].
    """

    nodes: list[NodeSpec] = field(default_factory=list)
    use_sim_time: bool = False
    log_dir: str | None = None
    stop_timeout: float = 5.0

    def __post_init__(self) -> None:
        labels = [n.label for n in self.nodes]
        dup = sorted({x for x in labels if labels.count(x) > 1})
        if dup:
            raise ValueError(f"node names must be unique per namespace: {dup}")


def _ros_params(value: Any) -> Any:
    """Params as ROS params files need them: no None values, and lists of numbers that mix
    integers and floats (``[0, 0.12]`` in YAML) all floats, since ROS rejects mixed arrays."""
    if isinstance(value, dict):
        return {k: _ros_params(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        items = [_ros_params(v) for v in value]
        numbers = [v for v in items if isinstance(v, (int, float)) and not isinstance(v, bool)]
        if numbers and len(numbers) == len(items) and any(isinstance(v, float) for v in numbers):
            return [float(v) for v in items]
        return items
    return value


class Launcher:
    """Start, watch and stop a set of node processes.

    Args:
        config: the nodes.
        log: where the prefixed output lines of all nodes go.
        base_dir: folder relative ``params_files`` and ``log_dir`` are resolved against.
    """

    def __init__(self, config: LaunchConfig, log: TextIO = sys.stdout, base_dir: str | Path = "."):
        self.config = config
        self.log = log
        self.base_dir = Path(base_dir)
        self.procs: list[tuple[NodeSpec, subprocess.Popen]] = []
        self.lines: dict[str, int] = {}
        self._tmp = tempfile.TemporaryDirectory(prefix="mrslam_launch_")
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._logged: set[str] = set()

    def _path(self, p: str) -> Path:
        path = Path(p)
        return path if path.is_absolute() else self.base_dir / path

    def _params_file(self, spec: NodeSpec) -> Path:
        params = dict(_ros_params(spec.params))
        params["use_sim_time"] = self.config.use_sim_time if spec.use_sim_time is None else spec.use_sim_time
        path = Path(self._tmp.name) / f"{spec.label.replace('/', '_')}.yaml"
        path.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
        return path

    def command(self, spec: NodeSpec) -> list[str]:
        """The command line of ``spec``'s process.

        Raises:
            ConfigError: a params file of ``spec`` does not exist.
        """
        cmd = [*spec.prefix, sys.executable, "-m", spec.module, *spec.args, "--ros-args", "-r", f"__node:={spec.name}"]
        if spec.namespace.strip("/"):
            cmd += ["-r", f"__ns:=/{spec.namespace.strip('/')}"]
        for src, dst in spec.remap.items():
            cmd += ["-r", f"{src}:={dst}"]
        for f in spec.params_files:
            path = self._path(f)
            if not path.is_file():
                raise ConfigError(f"node {spec.label}: params file {path} not found")
            cmd += ["--params-file", str(path)]
        cmd += ["--params-file", str(self._params_file(spec))]
        return cmd

    def _pump(self, spec: NodeSpec, proc: subprocess.Popen) -> None:
        label = f"[{spec.label}]"
        logfile = None
        if self.config.log_dir:
            folder = self._path(self.config.log_dir)
            folder.mkdir(parents=True, exist_ok=True)
            mode = "a" if spec.label in self._logged else "w"  # a restarted node continues its log
            self._logged.add(spec.label)
            logfile = (folder / f"{spec.label.replace('/', '_')}.log").open(mode)
        try:
            for line in proc.stdout:  # type: ignore[union-attr]
                with self._lock:
                    self.lines[spec.label] = self.lines.get(spec.label, 0) + 1
                    self.log.write(f"{label} {line}")
                    self.log.flush()
                if logfile:
                    logfile.write(line)
                    logfile.flush()
        finally:
            if logfile:
                logfile.close()

    def start(self) -> None:
        """Start every node (their output is pumped by background threads).

        Raises:
            ConfigError: a params file of the config does not exist (nothing is started then).
        """
        commands = [(spec, self.command(spec)) for spec in self.config.nodes]
        for spec, cmd in commands:
            self.procs.append((spec, self._spawn(spec, cmd)))

    def _spawn(self, spec: NodeSpec, cmd: list[str]) -> subprocess.Popen:
        from mrslam_ros.env import node_env

        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                env=node_env(extra=spec.env), start_new_session=True)
        t = threading.Thread(target=self._pump, args=(spec, proc), daemon=True)
        t.start()
        self._threads.append(t)
        return proc

    def _find(self, label: str) -> int:
        for i, (spec, _) in enumerate(self.procs):
            if spec.label == label:
                return i
        raise KeyError(f"no node {label!r} (have {[s.label for s, _ in self.procs]})")

    def send_signal(self, label: str, sig: int) -> None:
        """Send ``sig`` to the process group of node ``label`` (fault injection, pausing)."""
        _, proc = self.procs[self._find(label)]
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass

    def restart(self, label: str, args: list[str] | None = None, timeout: float = 10.0) -> None:
        """Start node ``label`` again (after killing it if it still runs), with ``args`` in place of
        its spec's extra arguments when given (e.g. ``["--resume"]``)."""
        i = self._find(label)
        spec, proc = self.procs[i]
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=timeout)
        if args is not None:
            spec = replace(spec, args=list(args))
        self.procs[i] = (spec, self._spawn(spec, self.command(spec)))

    def cpu_seconds(self) -> dict[str, float]:
        """CPU time (user + system) [s] each running node's process has used so far, by label
        (from /proc; empty where it is not readable, e.g. off Linux)."""
        out = {}
        tick = os.sysconf("SC_CLK_TCK")
        for spec, proc in self.procs:
            try:
                fields = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            out[spec.label] = (int(fields[11]) + int(fields[12])) / tick  # utime, stime (fields 14, 15)
        return out

    def exited(self) -> dict[str, int]:
        """Exit codes of the nodes that have exited, by label (negative: killed by that signal)."""
        return {s.label: p.returncode for s, p in self.procs if p.poll() is not None}

    def failed(self) -> list[str]:
        """Labels of the ``required`` nodes that have exited (whatever their exit code)."""
        return [s.label for s, p in self.procs if s.required and p.poll() is not None]

    def wait(self, poll: float = 0.1, timeout: float | None = None) -> list[str]:
        """Block until a required node exits (returns :meth:`failed`) or ``timeout`` [s] passes."""
        end = None if timeout is None else time.monotonic() + timeout
        while not self.failed() and (end is None or time.monotonic() < end):
            time.sleep(poll)
        return self.failed()

    def stop(self, timeout: float | None = None) -> dict[str, int]:
        """Stop every node: SIGINT, then SIGTERM, then SIGKILL to each process group, each followed
        by up to ``timeout`` s (default ``config.stop_timeout``) of waiting. Returns the exit codes."""
        timeout = self.config.stop_timeout if timeout is None else timeout
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [p for _, p in self.procs if p.poll() is None]
            if not alive:
                break
            for p in alive:
                try:
                    os.killpg(p.pid, sig)
                except ProcessLookupError:
                    pass
            end = time.monotonic() + timeout
            while time.monotonic() < end and any(p.poll() is None for p in alive):
                time.sleep(0.05)
        for _, p in self.procs:
            p.wait()
        for t in self._threads:
            t.join(timeout=2.0)
        self._tmp.cleanup()
        return self.exited()


def add_view_arguments(ap: argparse.ArgumentParser) -> None:
    """``--view``, ``--view-port``, ``--view-host``, ``--view-ellipsoids``: the options of every
    command that can start the view node (:mod:`mrslam_ros.view_node`)."""
    ap.add_argument("--view", action="store_true",
                    help="also serve a live Foxglove WebSocket view (open ws://HOST:PORT in Foxglove, "
                         "config/foxglove_layout.json for the panels)")
    ap.add_argument("--view-port", type=int, help="the view's TCP port (default: the view node's, 8765)")
    ap.add_argument("--view-host", help="address the view listens on (default 127.0.0.1; 0.0.0.0 for every interface)")
    ap.add_argument("--view-ellipsoids", action="store_true",
                    help="also stream the landmarks' covariance ellipsoids (the central node then builds them)")


def view_spec(args: argparse.Namespace, robots: list[str] | tuple[str, ...] = ()) -> NodeSpec:
    """The view node of a command line with :func:`add_view_arguments` (``robots`` empty: the
    node finds them in the graph)."""
    params: dict[str, Any] = {"robots": list(robots)}
    if args.view_port is not None:
        params["port"] = args.view_port
    if args.view_host:
        params["host"] = args.view_host
    if args.view_ellipsoids:
        params["ellipsoids"] = True
    # a view that cannot start (its port taken) must not stop the team
    return NodeSpec(module="mrslam_ros.view_node", name="view", params=params, required=False)


def _robot_namespaces(cfg: LaunchConfig) -> list[str]:
    """The namespaces of a launch config's frontend nodes: its robots."""
    return sorted({n.namespace.strip("/") for n in cfg.nodes if n.module == "mrslam_ros.frontend_node" and n.namespace})


class _Stop(Exception):
    """SIGTERM to the launcher."""


def _raise_stop(signum, frame) -> None:
    raise _Stop()


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam launch", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", help="launch YAML (see above)")
    ap.add_argument("--log-dir", help="write one log file per node here (overrides the config's log_dir)")
    ap.add_argument("--dry-run", action="store_true", help="check the config and print the commands only")
    add_view_arguments(ap)
    args = ap.parse_args(argv)
    try:
        cfg = load_yaml(LaunchConfig, args.config)
        if args.log_dir:
            cfg = replace(cfg, log_dir=str(Path(args.log_dir).resolve()))
        if args.view:
            cfg = replace(cfg, nodes=[*cfg.nodes, view_spec(args, _robot_namespaces(cfg))])
        launcher = Launcher(cfg, base_dir=Path(args.config).resolve().parent)
        for spec in cfg.nodes:
            launcher.command(spec)  # check the params files before starting anything
    except (ConfigError, OSError) as exc:
        print(f"mrslam launch: {exc}", file=sys.stderr)
        return 2
    if not cfg.nodes:
        print("mrslam launch: the config lists no nodes", file=sys.stderr)
        return 2
    if args.dry_run:
        for spec in cfg.nodes:
            print(" ".join(launcher.command(spec)))
        launcher.stop()
        return 0
    # a launcher started with SIGINT ignored (a background job of a non-interactive shell passes
    # SIG_IGN on, and Python then installs no handler) would sit through Ctrl-C
    signal.signal(signal.SIGINT, signal.default_int_handler)
    previous = signal.signal(signal.SIGTERM, _raise_stop)
    interrupted = False
    failed: list[str] = []
    launcher.start()
    print(f"mrslam launch: started {', '.join(s.label for s in cfg.nodes)}", file=sys.stderr, flush=True)
    try:
        failed = launcher.wait()
        print(f"mrslam launch: {', '.join(failed)} exited ({launcher.exited()}); stopping the others",
              file=sys.stderr, flush=True)
    except (KeyboardInterrupt, _Stop):
        interrupted = True
        print("mrslam launch: stopping", file=sys.stderr, flush=True)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not break the shutdown
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        codes = launcher.stop()
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, previous)
    print(f"mrslam launch: exit codes {codes}", file=sys.stderr, flush=True)
    if interrupted:
        return 0
    return 0 if all(codes.get(label) == 0 for label in failed) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
