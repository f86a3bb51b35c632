"""The ``azimut`` command line: one subcommand per job, each implemented next to what it runs.

A subcommand lives in a module that defines ``add_arguments(parser)`` and ``run(args) -> int``,
and optionally ``check_args(args)``, which raises ``ValueError`` for argument combinations that
``type=`` converters cannot see. Modules are imported only when their subcommand runs, so
``azimut bench-estimators`` does not pay for pymunk or torch.

Every argument and output path is checked before a command starts work (``type=`` converters of
:mod:`jobs.args`, then ``check_args``): a mistake is one line on stderr,
``azimut CMD: error: ...``, and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
import threading

#: name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "eval": ("jobs.eval.command", "run controllers on tracks and write a report (the main job)"),
    "bench-campaign": ("jobs.bench_campaign", "time an eval campaign serially and on N workers (same metrics?)"),
    "bench-estimators": ("jobs.bench_estimators",
                         "benchmark the ICR estimators on D1/D2/D3 (paper Table 1, Fig. 11-12)"),
    "bench-env": ("jobs.bench_env", "measure simulator throughput (steps/s) with a time breakdown"),
    "sim-paper": ("jobs.sim_paper", "the paper's phenomenon: the steering's departure from the constraining surface "
                  "while moving under the ICR controller, with one counterfactual per cause (compliance, friction, "
                  "quantisation, imperfections, motor lag)"),
    "record-d2": ("jobs.record_d2", "regenerate dataset D2 from the simulated robot on the paper track"),
    "estimate": ("jobs.estimate.command", "estimate the ICR, the H state and odometry from a recorded robot log "
                 "(CSV, ROS 2 bag, WPILib .wpilog)"),
    "calibrate": ("jobs.calibrate.command", "fit each module's steering offset and wheel-speed factor to a log of "
                  "ordinary driving (CSV, ROS 2 bag, WPILib .wpilog)"),
    "train": ("jobs.training.command", "train an RL baseline (needs the [rl] extra)"),
    "tune": ("jobs.training.tune", "search azimut train's hyperparameters with Optuna (the [tune] extra)"),
}


class CommandParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr and exit status 2."""

    def error(self, message: str):  # type: ignore[override]
        # one line even when an argument holds a line break or another control character
        message = "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)
        self.exit(2, f"{self.prog}: error: {message}\n")


def _available() -> dict[str, tuple[str, str]]:
    out = {}
    for name, (module, help_) in COMMANDS.items():
        if importlib.util.find_spec(module.split(".")[0]) is None:
            continue
        try:
            if importlib.util.find_spec(module) is None:
                continue
        except ModuleNotFoundError:
            continue
        out[name] = (module, help_)
    return out


def _version() -> str:
    """The installed package's version (``pyproject.toml``), or "unknown" from a source tree."""
    from importlib import metadata

    try:
        return metadata.version("azimut")
    except metadata.PackageNotFoundError:
        return "unknown"


#: seconds a command runs, with the numba cache cold, before :func:`_compile_notice` speaks
NOTICE_DELAY_S = 5.0


class _CompileCounter:
    """Counts numba's compilations (its ``numba:compile`` events; a kernel loaded from the on-disk
    cache raises none), so that the notice speaks only while kernels are really being compiled."""

    def __init__(self) -> None:
        import numba.core.event as numba_event

        self.count = 0
        counter = self

        class _Listener(numba_event.Listener):
            def on_start(self, event) -> None:
                counter.count += 1

            def on_end(self, event) -> None:
                pass

        self._event, self._listener = numba_event, _Listener()
        numba_event.register("numba:compile", self._listener)

    def close(self) -> None:
        self._event.unregister("numba:compile", self._listener)


def _compile_notice(name: str, delay: float = 0.0, compiles: _CompileCounter | None = None) -> threading.Timer | None:
    """One line on stderr when numba compiles kernels (a first run after an install or an update):
    the first progress line comes a minute or two later. On a terminal and off one (CI, nohup,
    notebooks, where the silence was the longest). ``main`` starts it once every argument is
    checked, ``delay`` seconds into the work (a timer it cancels when the command ends), and it
    speaks only if numba has compiled something since ``compiles`` started counting (kernels loaded
    from the cache do not count), so that a refusal, a quick error or a warm run stays silent.
    Returns the timer (None: printed now, or nothing to say)."""
    from estimation.numba_cache import CACHE_DIR

    if CACHE_DIR is None:
        return None

    def say() -> None:
        if compiles is None or compiles.count:
            print(f"azimut {name}: compiling the numba kernels (the first run of this version: a minute or two; "
                  f"cached in {CACHE_DIR})", file=sys.stderr, flush=True)

    if delay <= 0:
        say()
        return None
    timer = threading.Timer(delay, say)
    timer.daemon = True
    timer.start()
    return timer


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    commands = _available()
    parser = argparse.ArgumentParser(prog="azimut", description="AZIMUT-3 simulator, ICR estimation and control.")
    parser.add_argument("--version", action="store_true", help="print the package version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, help_) in commands.items():
        sub.add_parser(name, help=help_, add_help=False)
    if not argv:
        print(f"azimut: error: a command is required (choose from {', '.join(commands)}; azimut --help)",
              file=sys.stderr)
        return 2
    if argv[0] == "--version":
        print(f"azimut {_version()}")
        return 0
    if argv[0] in ("-h", "--help") or argv[0] not in commands:
        if argv[0] not in ("-h", "--help"):
            print(f"azimut: error: unknown command {argv[0]!r} (choose from {', '.join(commands)})", file=sys.stderr)
            return 2
        parser.print_help()
        return 0
    name = argv[0]
    compiles = _CompileCounter()  # before the command's import: importing compiles some kernels
    try:
        return _run_command(name, commands, argv, compiles)
    finally:
        compiles.close()


def _run_command(name: str, commands: dict, argv: list[str], compiles: _CompileCounter) -> int:
    module = importlib.import_module(commands[name][0])
    cmd_parser = CommandParser(prog=f"azimut {name}", description=commands[name][1])
    module.add_arguments(cmd_parser)
    try:
        args = cmd_parser.parse_args(argv[1:])
        from jobs.args import check_robot_stability

        for check in (getattr(module, "check_args", None), check_robot_stability):
            if check is None:
                continue
            try:
                check(args)
            except (ValueError, TypeError) as exc:
                cmd_parser.error(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    except SystemExit as exc:  # --help (0) or a refused argument (2): a return code, as for run()
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    notice = _compile_notice(name, NOTICE_DELAY_S, compiles)
    from jobs.interrupts import EXIT_STATUS, signals_as_interrupts

    try:
        with signals_as_interrupts() as state:
            return int(module.run(args) or 0)
    except KeyboardInterrupt:  # a command without its own handling (eval, train and tune have theirs)
        sig = state["signal"]
        print(f"azimut {name}: interrupted ({sig.name}) before it finished: any output it was writing is "
              "incomplete; run it again", file=sys.stderr)
        return EXIT_STATUS[sig]
    except ConnectionError as exc:
        from jobs.campaign.engine import ClusterUnreachable
        if not isinstance(exc, ClusterUnreachable):
            raise
        print(f"azimut {name}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        if notice is not None:
            notice.cancel()


if __name__ == "__main__":
    raise SystemExit(main())
