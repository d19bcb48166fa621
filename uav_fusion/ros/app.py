"""The one node runtime: how every executable of the package starts and ends.

:func:`run_app` is the body of every ``main()`` (``radar_replay``, ``rf_replay``,
``truth_replay``, ``fusion_node``, ``evaluator_node``, ``bag_player``, ``bag_recorder``,
``graph``):

1. **Arguments.** ``rclpy.init`` takes the ROS arguments (``--ros-args ...``); the rest (the
   program name dropped) goes to the app's builder, which may refuse it with
   :class:`UsageError` (exit 2, the usage text on stderr).
2. **Signals.** SIGINT and SIGTERM set a stop flag (rclpy's own handlers are off, so the
   context stays usable for a last drain, flush or report); a second signal exits at once
   with :data:`EXIT_FORCED`.
3. **Start.** The builder returns an :class:`App` (its nodes and hooks). A
   :class:`~uav_fusion.core.errors.UavFusionError` while building (bad parameter, missing
   file, unreadable data) is logged and gives :data:`EXIT_CONFIG`, never a traceback. One
   log line names the executable and every effective parameter of its nodes.
4. **Spin** on one executor until a signal, until :attr:`App.finished` says the work is
   done, or until the context is shut down; an app that owns its loop (``graph``) runs
   :attr:`App.run` instead, which polls the stop flag.
5. **Stop.** :attr:`App.on_stop` (flush, drain, write a report) with the context still
   valid, then the nodes are destroyed and rclpy shut down, all bounded by a watchdog of
   :attr:`App.stop_grace_s` seconds: if the teardown hangs (DDS while peers vanish, a stuck
   hook) the process says so and exits with :data:`EXIT_FORCED`. A teardown stuck inside a
   call that keeps the interpreter locked (rclpy calls into the middleware without releasing
   it, so a blocked DDS call freezes every Python thread, the watchdog's too) is ended by a
   second watchdog that needs no interpreter (:mod:`faulthandler`): :data:`HARD_EXIT_SLACK_S`
   later it writes every thread's stack to stderr, which shows where it hung, and exits with
   status 1.

Exit status: :data:`EXIT_OK` on a clean stop (signal or work done), :data:`EXIT_FAILED` when
the app failed (an exception in a callback, or :attr:`App.status` says so),
:data:`EXIT_CONFIG` on a bad set-up, :data:`EXIT_FORCED` when the watchdog or a second signal
forced the exit.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from types import FrameType
from typing import Any

from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from uav_fusion.core.errors import UavFusionError

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_CONFIG = 2
EXIT_FORCED = 3

#: Default wall seconds the teardown (stop hook, node destruction, rclpy shutdown) may take.
SHUTDOWN_GRACE_S = 10.0
#: Seconds after the grace at which the interpreter-independent watchdog ends the process.
HARD_EXIT_SLACK_S = 2.0


class UsageError(UavFusionError):
    """Wrong plain (non-ROS) command-line arguments; the text is the usage line."""


def _noop(*_args: Any) -> None:
    return None


def _never() -> bool:
    return False


def _ok() -> int:
    return EXIT_OK


@dataclass
class App:
    """What :func:`run_app` runs: nodes and the hooks of their life cycle.

    ``start`` runs once the nodes are built, ``finished`` is polled between spins (True: the
    work is done, stop), ``run`` replaces the spin loop for an app that owns its executor (it
    gets the stop flag and returns an exit status), ``on_stop`` runs before the teardown
    with the executor (the context still valid unless the middleware shut it), ``status``
    gives the exit status of a run that was not interrupted by an error.
    """

    name: str
    nodes: Sequence[Node]
    start: Callable[[], None] = _noop
    finished: Callable[[], bool] = _never
    run: Callable[[Callable[[], bool]], int] | None = None
    on_stop: Callable[[Executor | None], None] = _noop
    status: Callable[[], int] = _ok
    stop_grace_s: float = SHUTDOWN_GRACE_S
    executor: Executor | None = None
    extra: dict[str, Any] = field(default_factory=dict)  # logged with the parameters


def effective_parameters(node: Node) -> dict[str, Any]:
    """Every parameter of ``node`` (``use_sim_time`` included) and its value."""
    params: dict[str, Any] = dict(node.get_parameters_by_prefix(""))  # name -> Parameter
    return {
        name: p.value for name, p in sorted(params.items())
        if name != "start_type_description_service"
    }


def startup_line(app: App) -> str:
    """The one log line that says what runs, with which parameters."""
    parts = []
    for node in app.nodes:
        params = ", ".join(f"{k}={v!r}" for k, v in effective_parameters(node).items())
        parts.append(f"{node.get_name()} [{params}]")
    extra = "".join(f"; {k}={v!r}" for k, v in app.extra.items())
    return f"{app.name} started: " + "; ".join(parts) + extra


class _Watchdog:
    """Forces the process out if the teardown does not finish in time (module text, step 5):
    a timer thread, and behind it faulthandler's, which runs without the interpreter."""

    def __init__(self, name: str, grace_s: float) -> None:
        self.name = name
        self.grace_s = grace_s
        self._timer = threading.Timer(grace_s, self._fire)
        self._timer.daemon = True
        self._hard = False

    def _fire(self) -> None:
        print(
            f"{self.name}: warning: shutdown did not finish within {self.grace_s:g} s; "
            f"forcing the exit (status {EXIT_FORCED})",
            file=sys.stderr,
            flush=True,
        )
        os._exit(EXIT_FORCED)

    def __enter__(self) -> _Watchdog:
        self._timer.start()
        err = sys.__stderr__
        try:
            if err is not None:
                faulthandler.dump_traceback_later(
                    self.grace_s + HARD_EXIT_SLACK_S, exit=True, file=err
                )
                self._hard = True
        except (OSError, ValueError, RuntimeError):  # no usable stderr descriptor
            self._hard = False
        return self

    def __exit__(self, *_exc: object) -> None:
        self._timer.cancel()
        if self._hard:
            faulthandler.cancel_dump_traceback_later()


class _Signals:
    """SIGINT/SIGTERM set :attr:`stop`; a second one exits at once (main thread only)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.stop = threading.Event()
        self._previous: dict[int, Any] = {}

    def _handle(self, signum: int, _frame: FrameType | None) -> None:
        if self.stop.is_set():
            print(f"{self.name}: second signal: exiting now", file=sys.stderr, flush=True)
            os._exit(EXIT_FORCED)
        self.stop.set()

    def __enter__(self) -> _Signals:
        if threading.current_thread() is threading.main_thread():
            for s in (signal.SIGINT, signal.SIGTERM):
                self._previous[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *_exc: object) -> None:
        for s, h in self._previous.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


def plain_args(argv: Sequence[str]) -> list[str]:
    """The non-ROS arguments after the program name."""
    from rclpy.utilities import remove_ros_args

    return list(remove_ros_args(list(argv))[1:])


def run_app(
    name: str, build: Callable[[list[str]], App], args: Sequence[str] | None = None
) -> int:
    """Initialise rclpy, build the app, spin it and tear it down (see the module docstring).

    ``args`` is a full argument vector (program name first); None means ``sys.argv``.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    argv = list(sys.argv if args is None else args)
    if not argv:
        argv = [name]
    with _Signals(name) as signals:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
        app: App | None = None
        code = EXIT_OK
        try:
            try:
                app = build(plain_args(argv))
            except UsageError as exc:
                print(f"usage: {exc}", file=sys.stderr)
                return EXIT_CONFIG
            except UavFusionError as exc:
                rclpy.logging.get_logger(name).error(str(exc))
                print(f"{name}: error: {exc}", file=sys.stderr)
                return EXIT_CONFIG
            if app.nodes:
                app.nodes[0].get_logger().info(startup_line(app))
            code = _spin(app, signals.stop)
        except Exception:
            print(f"{name}: error: the node failed:\n{traceback.format_exc()}", file=sys.stderr)
            code = EXIT_FAILED
        finally:
            grace = app.stop_grace_s if app is not None else SHUTDOWN_GRACE_S
            with _Watchdog(name, grace):
                code = _teardown(app, code)
        return code


def _spin(app: App, stop: threading.Event) -> int:
    from rclpy.utilities import ok

    app.start()
    if app.run is not None:
        return app.run(stop.is_set)
    executor = app.executor
    if executor is None:
        executor = app.executor = SingleThreadedExecutor()
        for node in app.nodes:
            executor.add_node(node)
    while not stop.is_set() and ok():
        try:
            executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            break
        except RuntimeError:
            # the context was shut down while a message was being taken: a normal stop
            if ok():
                raise
            break
        if app.finished():
            break
    return app.status()


def _teardown(app: App | None, code: int) -> int:
    from rclpy.utilities import try_shutdown

    try:
        if app is not None:
            try:
                app.on_stop(app.executor)
            except Exception:
                print(f"{app.name}: error while stopping:\n{traceback.format_exc()}",
                      file=sys.stderr)
                code = code or EXIT_FAILED
            if app.executor is not None:
                app.executor.shutdown(timeout_sec=1.0)
            for node in reversed(list(app.nodes)):
                node.destroy_node()
    finally:
        try_shutdown()
    return code


def node_app(
    node: Node,
    *,
    start: Callable[[], None] = _noop,
    finished: Callable[[], bool] = _never,
    on_stop: Callable[[Executor | None], None] = _noop,
    status: Callable[[], int] = _ok,
    stop_grace_s: float = SHUTDOWN_GRACE_S,
) -> App:
    """An :class:`App` of one node."""
    return App(node.get_name(), [node], start=start, finished=finished, on_stop=on_stop,
               status=status, stop_grace_s=stop_grace_s)


def run_node(
    factory: Callable[..., Node],
    args: Sequence[str] | None = None,
    *,
    finished: Callable[[Node], bool] | None = None,
    on_stop: Callable[[Node, Executor | None], None] | None = None,
    start: Callable[[Node], None] | None = None,
    name: str | None = None,
    stop_grace_s: float = SHUTDOWN_GRACE_S,
) -> int:
    """:func:`run_app` for one node built by ``factory()`` without plain arguments."""
    label = str(name or getattr(factory, "__name__", "node"))

    def build(plain: list[str]) -> App:
        if plain:
            raise UsageError(f"{label} [--ros-args -p name:=value ...] (unexpected: {plain})")
        node = factory()
        fin, stop, st = finished, on_stop, start
        return node_app(
            node,
            start=(lambda: st(node)) if st is not None else _noop,
            finished=(lambda: fin(node)) if fin is not None else _never,
            on_stop=(lambda ex: stop(node, ex)) if stop is not None else _noop,
            stop_grace_s=stop_grace_s,
        )

    return run_app(label, build, args)
