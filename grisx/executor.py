"""Executors: where the independent tasks of a reference or a study run.

A high-spp reference is a sum over disjoint sample chunks, and a study is a
set of (scene, method, seed) jobs; neither needs its pieces to run in one
process. An :class:`Executor` runs a list of :class:`Task` records — a
module-level function and its keyword arguments — and hands each result back
to the caller, in the caller's process, as soon as it is done:

* :class:`InProcessExecutor` — one device, here, in order (the default; what
  every single-device command does);
* :class:`DeviceExecutor` — one worker process per entry of ``--devices``
  (``cuda:0,cuda:1`` or, for tests, ``cpu,cpu``), each running one task at a
  time on its device;
* :class:`RayExecutor` — one Ray task per :class:`Task` asking for
  ``num_gpus=1`` (or one CPU), on a local Ray instance or on the cluster at
  ``address`` (``grisx[cluster]``; Ray is the engine, grisx adds no scheduler).

Every executor passes ``device=`` (the device the task runs on) to the task's
function, retries a task that fails — it raised an error other than a
:class:`~grisx.errors.GrisxError` (bad input fails the same way every time),
or its worker process died — up to ``retries`` times, and records every
attempt in :attr:`Executor.reports`, so a command can say what was retried.

Tasks must not depend on where or in which order they run: results are keyed
by :attr:`Task.key` and combined by the caller in a fixed order (a reference
merges its chunks by chunk index), which makes the combined result the same
on every executor.
"""

from __future__ import annotations

import dataclasses
import os
import re
import socket
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from grisx.errors import DeviceError, GrisxError, InvalidParameterError

__all__ = [
    "Task",
    "TaskReport",
    "Executor",
    "InProcessExecutor",
    "DeviceExecutor",
    "RayExecutor",
    "EXECUTORS",
    "parse_devices",
    "make_executor",
]

#: executor names of ``--executor``
EXECUTORS = ("local", "ray")


@dataclasses.dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(**kwargs, device=...)`` named ``key`` (unique within one run)."""

    key: str
    fn: Callable[..., Any]
    kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class TaskReport:
    """What happened to one task: where it ran, how many attempts, the errors of the failed ones."""

    key: str
    device: str = ""
    worker: str = ""  # names the worker: the device, 'cpu#1' for one of several logical workers, or host:device
    host: str = ""
    attempts: int = 0
    seconds: float = 0.0
    errors: list[str] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class _Failed:
    """A task attempt that failed: ``retry`` says whether another attempt may succeed."""

    def __init__(self, message: str, retry: bool, error: BaseException | None = None):
        self.message, self.retry, self.error = message, retry, error


def _call(fn: Callable[..., Any], kwargs: dict[str, Any], device: str) -> tuple[Any, str, str, float]:
    """Run one task where it was sent: (result, device, host, seconds)."""
    start = time.perf_counter()
    value = fn(**kwargs, device=device)
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    where = f"{device}[gpu {visible}]" if device.startswith("cuda") and visible else device
    return value, where, socket.gethostname(), time.perf_counter() - start


def _portable_call(fn: Callable[..., Any], kwargs: dict[str, Any], device: str) -> tuple[Any, str, str, float]:
    """:func:`_call` in a worker process: an error that would not survive pickling comes back as one that does.

    (An exception crosses back to the caller pickled; one whose constructor takes other arguments than its
    message, such as :class:`~grisx.errors.UnknownNameError`, would fail to unpickle there.)
    """
    import pickle

    try:
        return _call(fn, kwargs, device)
    except Exception as exc:
        try:
            same = str(pickle.loads(pickle.dumps(exc))) == str(exc)
        except Exception:  # noqa: BLE001
            same = False
        if same:
            raise
        if isinstance(exc, GrisxError):
            raise GrisxError(str(exc)) from None
        raise RuntimeError(_message(exc)) from None


class Executor:
    """Runs tasks and streams their results back; see the module docstring."""

    name = "executor"

    def __init__(self, devices: Sequence[str], retries: int = 1) -> None:
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise InvalidParameterError(f"retries must be a non-negative integer, got {retries!r}")
        self.devices = tuple(devices)
        self.retries = retries
        self.reports: list[TaskReport] = []

    # ---- what an executor implements: start an attempt, wait for one to finish ----
    def _start(self, task: Task, slot: int) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def _wait(self, running: dict[Any, tuple[Task, int]]) -> tuple[Any, Any]:  # pragma: no cover - abstract
        """Block until one of ``running``'s handles finishes: (handle, (value, device, host, s) or _Failed)."""
        raise NotImplementedError

    def slots(self) -> int:
        """How many tasks may run at once."""
        return len(self.devices)

    def _worker(self, slot: int, report: TaskReport) -> str:
        """The name of the worker that ran a task, for per-device throughput."""
        device = self.devices[slot]
        return f"{device}#{slot}" if self.devices.count(device) > 1 else device

    def close(self) -> None:
        """Release workers (a no-op for executors that hold none)."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def describe(self) -> dict[str, Any]:
        return {"executor": self.name, "devices": list(self.devices), "retries": self.retries}

    def run(self, tasks: Iterable[Task]) -> Iterator[tuple[Task, Any, TaskReport]]:
        """Run ``tasks``; yield (task, result, report) as each one finishes (completion order).

        A task that still fails after ``retries`` retries raises a
        :class:`~grisx.errors.GrisxError` naming it (after the tasks already
        running have finished, so their results are not lost to the caller).
        """
        pending = list(tasks)
        keys = [t.key for t in pending]
        if len(set(keys)) != len(keys):
            raise InvalidParameterError("task keys must be unique within one run")
        pending.reverse()  # pop() takes them in the given order
        reports = {t.key: TaskReport(t.key) for t in pending}
        running: dict[Any, tuple[Task, int]] = {}
        free = list(range(self.slots()))[::-1]
        failure: GrisxError | None = None
        while pending or running:
            while pending and free and failure is None:
                task, slot = pending.pop(), free.pop()
                reports[task.key].attempts += 1
                running[self._start(task, slot)] = (task, slot)
            if not running:
                break
            handle, outcome = self._wait(running)
            task, slot = running.pop(handle)
            free.append(slot)
            report = reports[task.key]
            if isinstance(outcome, _Failed):
                report.errors.append(outcome.message)
                if outcome.retry and report.attempts <= self.retries and failure is None:
                    pending.append(task)  # next in line
                    continue
                self.reports.append(report)
                if failure is None:
                    if isinstance(outcome.error, GrisxError):
                        failure = outcome.error
                    else:
                        tries = f" after {report.attempts} attempts" if report.attempts > 1 else ""
                        failure = GrisxError(f"task {task.key} failed{tries}: {outcome.message}")
                continue
            value, report.device, report.host, report.seconds = outcome
            report.worker = self._worker(slot, report)
            self.reports.append(report)
            yield task, value, report
        if failure is not None:
            raise failure

    @property
    def retried(self) -> list[dict[str, Any]]:
        """Reports of the tasks that needed more than one attempt."""
        return [r.to_dict() for r in self.reports if r.attempts > 1]


def _message(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


class InProcessExecutor(Executor):
    """Runs each task here, at once, on one device."""

    name = "local"

    def __init__(self, device: str = "cpu", retries: int = 1) -> None:
        super().__init__([device], retries)

    def _start(self, task: Task, slot: int) -> Any:
        try:
            outcome: Any = _call(task.fn, task.kwargs, self.devices[slot])
        except GrisxError as exc:
            outcome = _Failed(str(exc), False, exc)
        except Exception as exc:  # noqa: BLE001 - any other failure may be transient: retry
            outcome = _Failed(_message(exc), True, exc)
        return _Done(outcome)

    def _wait(self, running: dict[Any, tuple[Task, int]]) -> tuple[Any, Any]:
        handle = next(iter(running))
        return handle, handle.outcome


class _Done:
    def __init__(self, outcome: Any) -> None:
        self.outcome = outcome


def _grisx_path() -> str:
    """The folder holding this grisx package (for workers of an uninstalled checkout)."""
    return str(Path(__file__).resolve().parent.parent)


def _worker_init() -> None:
    from grisx.device import init

    init()


class DeviceExecutor(Executor):
    """One worker process per device (``spawn``ed, so each has its own CUDA context); one task each at a time."""

    name = "devices"

    def __init__(self, devices: Sequence[str], retries: int = 1) -> None:
        super().__init__(devices, retries)
        self._pools: dict[int, Any] = {}

    def _pool(self, slot: int) -> Any:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        if slot not in self._pools:
            self._pools[slot] = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init)
        return self._pools[slot]

    def _start(self, task: Task, slot: int) -> Any:
        return self._pool(slot).submit(_portable_call, task.fn, task.kwargs, self.devices[slot])

    def _wait(self, running: dict[Any, tuple[Task, int]]) -> tuple[Any, Any]:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        done, _ = wait(list(running), return_when=FIRST_COMPLETED)
        future = next(iter(done))
        try:
            return future, future.result()
        except GrisxError as exc:
            return future, _Failed(str(exc), False, exc)
        except BrokenProcessPool as exc:
            slot = running[future][1]
            self._pools.pop(slot).shutdown(wait=False, cancel_futures=True)  # a fresh worker for the retry
            return future, _Failed(f"worker process on {self.devices[slot]} died ({exc})", True, exc)
        except Exception as exc:  # noqa: BLE001
            return future, _Failed(_message(exc), True, exc)

    def close(self) -> None:
        for pool in self._pools.values():
            pool.shutdown(wait=True, cancel_futures=True)
        self._pools.clear()


_ADDRESS = re.compile(r"^(auto|local|(ray://)?[A-Za-z0-9_.\-]+:\d{1,5})$")


class RayExecutor(Executor):
    """One Ray task per :class:`Task` (``num_gpus=1`` for cuda, one CPU for cpu), retried by grisx.

    ``address``: an existing cluster (``host:port``, ``ray://host:port`` or
    ``auto``), or None for a local Ray instance started here (``num_cpus``
    of this machine unless given). A local instance gets this checkout on its
    workers' ``PYTHONPATH``; a cluster gets this grisx package shipped with the
    job (Ray's ``py_modules``), so its nodes need grisx's dependencies (Warp,
    numpy, ...) but not grisx, and must be able to read any scene file named
    by path.
    """

    name = "ray"

    def __init__(self, device: str = "cpu", address: str | None = None, retries: int = 1, num_cpus: int | None = None) -> None:
        if device not in ("cpu", "cuda"):
            raise DeviceError(f"the ray executor runs tasks on 'cpu' or 'cuda' (one GPU each), got device '{device}'")
        if address is not None and not _ADDRESS.match(address):
            raise InvalidParameterError(f"--address must be host:port, ray://host:port or auto, got '{address}'")
        try:
            import ray
        except ImportError:
            raise GrisxError("the ray executor needs Ray: pip install 'grisx[cluster]' (or pip install ray)") from None
        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "logging_level": "ERROR"}
            if address is None or address == "local":
                path = os.pathsep.join(p for p in (_grisx_path(), os.environ.get("PYTHONPATH", "")) if p)
                kwargs["runtime_env"] = {"env_vars": {"PYTHONPATH": path}}
                if num_cpus is not None:
                    kwargs["num_cpus"] = int(num_cpus)
            else:
                _check_reachable(address)
                kwargs["address"] = address
                # this grisx travels with the job (Ray's py_modules): every node runs the driver's code
                kwargs["runtime_env"] = {"py_modules": [str(Path(__file__).resolve().parent)],
                                         "excludes": ["__pycache__", "*.pyc"]}
            try:
                ray.init(**kwargs)
            except Exception as exc:  # noqa: BLE001 - Ray raises ConnectionError, RuntimeError, ...
                raise GrisxError(f"cannot start or reach the Ray cluster at '{address or 'local'}': {_message(exc)}") from None
            self._started = True
        gpus = device == "cuda"
        total = ray.cluster_resources().get("GPU" if gpus else "CPU", 0)
        if total < 1:
            raise DeviceError(f"the Ray cluster at '{address or 'local'}' has no {'GPU' if gpus else 'CPU'} to run tasks on")
        super().__init__([device] * int(total), retries)
        self.address = address
        self._remote = ray.remote(_portable_call).options(num_gpus=1 if gpus else 0, num_cpus=0 if gpus else 1, max_retries=0)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "address": self.address or "local", "devices": [self.devices[0]] if self.devices else []}

    def _worker(self, slot: int, report: TaskReport) -> str:
        return f"{report.host}:{report.device}"

    def _start(self, task: Task, slot: int) -> Any:
        return self._remote.remote(task.fn, task.kwargs, self.devices[slot])

    def _wait(self, running: dict[Any, tuple[Task, int]]) -> tuple[Any, Any]:
        ray = self._ray
        done, _ = ray.wait(list(running), num_returns=1)
        ref = done[0]
        try:
            return ref, ray.get(ref)
        except ray.exceptions.RayTaskError as exc:  # the task raised: a GrisxError is final, others are retried
            cause = getattr(exc, "cause", None)
            if isinstance(cause, GrisxError):
                return ref, _Failed(str(cause), False, cause)
            return ref, _Failed(_message(cause) if cause is not None else _message(exc), True, exc)
        except ray.exceptions.RayError as exc:  # the worker died, the node was lost, ...
            return ref, _Failed(_message(exc), True, exc)

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()
            self._started = False


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """A one-line error at once for a cluster address nobody answers at (Ray itself would wait minutes)."""
    if address == "auto":
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise GrisxError(f"cannot reach the Ray cluster at '{address}': {exc.strerror or exc}") from None


def parse_devices(text: str) -> list[str]:
    """``"cuda:0,cuda:1"`` → ["cuda:0", "cuda:1"], each checked to exist (``cpu`` may repeat: logical workers)."""
    from grisx.device import resolve_device

    items = [s.strip() for s in str(text).split(",")]
    if not text or not all(items):
        raise InvalidParameterError(f"--devices expects a comma-separated list such as cuda:0,cuda:1, got '{text}'")
    for name in items:
        if not re.fullmatch(r"cpu|cuda(:\d+)?", name):
            raise DeviceError(f"unknown device '{name}' in --devices (use cpu, cuda or cuda:N)")
        resolve_device(name)
    gpus = [d for d in items if d != "cpu"]
    if len(set(gpus)) != len(gpus):
        raise InvalidParameterError(f"--devices names a GPU twice: '{text}'")
    return items


def make_executor(
    executor: str | None = None,
    *,
    device: str = "cpu",
    devices: Sequence[str] | str | None = None,
    address: str | None = None,
    retries: int = 1,
) -> Executor:
    """The executor that the command-line flags ask for (``--executor``, ``--device(s)``, ``--address``, ``--retries``)."""
    name = executor or "local"
    if name not in EXECUTORS:
        from grisx.errors import UnknownNameError

        raise UnknownNameError("executor", name, EXECUTORS)
    if isinstance(devices, str):
        devices = parse_devices(devices)
    if address is not None and name != "ray":
        raise InvalidParameterError("--address names a Ray cluster: give it with --executor ray")
    if name == "ray":
        if devices:
            raise InvalidParameterError("--devices picks local worker processes; with --executor ray, Ray picks the GPUs "
                                        "(give --device cuda)")
        return RayExecutor("cuda" if device.startswith("cuda") else "cpu", address=address, retries=retries)
    if devices and len(devices) > 1:
        return DeviceExecutor(devices, retries)
    if devices:
        device = devices[0]
    from grisx.device import resolve_device

    resolve_device(device)
    return InProcessExecutor(device, retries)


def add_executor_arguments(p: Any) -> None:
    """``--devices``, ``--executor``, ``--address``, ``--retries`` on a command that distributes its tasks."""
    p.add_argument("--devices", default=None, metavar="D,D,...",
                   help="one worker process per device, e.g. cuda:0,cuda:1 (cpu,cpu: two logical CPU workers)")
    p.add_argument("--executor", default=None, choices=EXECUTORS,
                   help="local (default: this process, or the --devices workers) or ray (one Ray task per chunk or job; "
                        "pip install 'grisx[cluster]')")
    p.add_argument("--address", default=None, help="with --executor ray: an existing cluster (host:port, ray://host:port, auto); "
                                                   "default: a local Ray instance")
    p.add_argument("--retries", type=int, default=1, help="retries of a failed task (default 1); retried tasks are reported")


def executor_from_args(args: Any) -> Executor:
    """The executor of :func:`add_executor_arguments`'s flags (and ``--device``)."""
    return make_executor(args.executor, device=args.device, devices=args.devices, address=args.address, retries=args.retries)
