"""The command-line side of campaigns: ``--seeds`` lists and ranges, and the executor flags
(``--workers``, ``--executor``, ``--ray-address``, ...) shared by ``azimut eval``, ``azimut train
--seeds`` and ``azimut bench-campaign``, checked before any work starts (a Ray address must
answer). The engine that runs the tasks is :mod:`jobs.campaign.engine`."""

from __future__ import annotations

import argparse
import re

from jobs.campaign.engine import EXECUTORS, resolve_executor

__all__ = ["parse_seeds", "arg_seeds", "add_executor_arguments", "check_ray_address", "check_executor_args"]


# ---------------------------------------------------------------------------------- seeds


def parse_seeds(text: str, max_count: int = 100_000) -> list[int]:
    """``"0-9"``, ``"0,3,5"`` or both (``"0-3,7"``) as a list of distinct non-negative ints, in order."""
    seeds: list[int] = []
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            raise ValueError(f"empty entry in seeds {text!r}")
        m = re.fullmatch(r"(\d+)\s*-\s*(\d+)", part)
        if m:
            lo, hi = int(m.group(1)), int(m.group(2))
            if hi < lo:
                raise ValueError(f"seed range {part!r} runs backwards")
            if hi - lo + 1 + len(seeds) > max_count:
                raise ValueError(f"more than {max_count} seeds in {text!r}")
            seeds.extend(range(lo, hi + 1))
        elif re.fullmatch(r"\d+", part):
            seeds.append(int(part))
        else:
            raise ValueError(f"seeds must be non-negative integers or ranges like 0-9, got {part!r}")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"repeated seed in {text!r}")
    if len(seeds) > max_count:
        raise ValueError(f"more than {max_count} seeds in {text!r}")
    return seeds


def arg_seeds(text: str) -> list[int]:
    """``type=`` converter for ``--seeds`` (one-line argparse error)."""
    try:
        return parse_seeds(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


arg_seeds.__name__ = "seeds"


# ---------------------------------------------------------------------------- command line


def add_executor_arguments(parser: argparse.ArgumentParser, what: str = "episodes", *, threads: bool = True,
                           resume: bool = True) -> None:
    """``--workers``, ``--executor``, ``--ray-address``, ``--threads`` (``--threads-per-task``), ``--retries``,
    ``--resume``: how a command runs its tasks (shared by the commands that run campaigns; a
    command with its own thread or resume flag leaves those out)."""
    from jobs.args import arg_int

    parser.add_argument("--workers", type=arg_int(1, 1024), default=1,
                        help=f"{what} run in parallel (default 1: serial, in this process)")
    parser.add_argument("--executor", choices=EXECUTORS, default="auto",
                        help="auto (default): Ray with --ray-address, else serial for 1 worker, else local "
                             "processes; 'ray' starts a local Ray instance (the 'cluster' extra)")
    parser.add_argument("--ray-address", default=None, metavar="ADDRESS",
                        help="join an existing Ray cluster ('auto' on one of its nodes, or HEAD_IP:6379) instead of "
                             "starting a local instance; every node needs this package installed")
    if threads:
        parser.add_argument("--threads", "--threads-per-task", dest="threads_per_task", type=arg_int(1, 1024),
                            default=None, metavar="N",
                            help="threads per task: the vector env's and controllers' compiled kernels (blocks of "
                                 "robots), torch, BLAS (default: CPUs // workers; serial: the cores this process may "
                                 "use); the results do not depend on it")
    parser.add_argument("--retries", type=arg_int(0, 10), default=1,
                        help="runs again a task that raised or whose worker died, this many times, before "
                             "reporting it as failed (default 1)")
    if resume:
        parser.add_argument("--resume", action="store_true",
                            help=f"keep the {what} already saved in the output folder and compute only the missing "
                                 f"ones (without it, saved {what} are discarded)")


def check_ray_address(address: str, timeout: float = 3.0) -> str:
    """Refuse a Ray address that cannot be reached before any work starts (``ValueError``, one line).

    ``auto`` is resolved the way ``ray.init`` resolves it (``RAY_ADDRESS``, else the cluster this
    machine last started); then the head's ``host:port`` (``ray://`` client addresses too) must
    accept a TCP connection within ``timeout`` seconds. Without this check ``ray.init`` retries an
    unreachable GCS for minutes and ``auto`` with no cluster ends in a ``ConnectionError`` traceback.
    Returns the ``host:port`` that answered."""
    import socket

    addr = str(address).strip()
    target = addr
    if addr == "auto" or addr == "local":
        if addr == "local":
            raise ValueError("--ray-address 'local' is not a cluster: leave --ray-address out and use "
                             "--executor ray to start a local Ray instance")
        try:
            from ray._private.services import canonicalize_bootstrap_address
            target = canonicalize_bootstrap_address("auto")
        except ImportError:
            raise ValueError("--ray-address needs Ray: pip install 'azimut[cluster]'") from None
        except (ConnectionError, ValueError, OSError) as exc:
            raise ValueError(f"--ray-address auto: no running Ray cluster found on this machine "
                             f"({' '.join(str(exc).split())})") from None
        if not target:
            raise ValueError("--ray-address auto: no running Ray cluster found on this machine")
    rest = target.split("://", 1)[1] if "://" in target else target
    host, sep, port = rest.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--ray-address must be 'auto' or HOST:PORT (e.g. 10.0.0.5:6379), got {addr!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as exc:
        reason = "timed out" if isinstance(exc, socket.timeout) else (exc.strerror or str(exc))
        where = addr if target == addr else f"{addr} ({target})"
        raise ValueError(f"--ray-address {where}: cannot reach a Ray head there within {timeout:g} s "
                         f"({reason})") from None
    return f"{host}:{port}"


def check_executor_args(args: argparse.Namespace) -> str:
    """Check the executor flags together; return the executor that will run (``ValueError``).
    A ``--ray-address`` must answer (:func:`check_ray_address`) before any work starts."""
    if args.ray_address is not None and not str(args.ray_address).strip():
        raise ValueError("--ray-address must not be empty")
    executor = resolve_executor(args.executor, args.workers, args.ray_address)
    threads = getattr(args, "threads_per_task", None)
    if threads is not None and args.ray_address is None:  # local tasks: at most this machine's pool
        from estimation.threads import check_threads

        check_threads(threads, "argument --threads")
    if args.ray_address is not None:
        check_ray_address(args.ray_address)
    return executor
