"""Have the simulation kernels ready before a lockstep twin's step clock starts.

numba compiles a kernel on its first call, or loads it from the on-disk cache
(:mod:`conveyor_twin.numba_cache`). With a cold cache on a loaded machine that takes minutes, far
more than the harness's ``timeout`` for one answer of the twin. So before a
:class:`~conveyor_twin.testing.LockstepTwin` starts, :func:`ready_kernels` runs the step path
once on a scratch twin of the cell (:func:`~conveyor_twin.coord.warmup.warm_up`) in a thread of
its own and waits for it with its own budget, :data:`COMPILE_BUDGET`; a wait longer than
:data:`NOTICE_AFTER` is announced on stderr. Later twins of the process find the kernels loaded
(a few tens of ms). The split layout's processes then load them from the cache this filled.

A compile cannot be interrupted: when the budget runs out, the error says so and the compile
goes on in its (non-daemon) thread, and at interpreter exit the process waits for any compile in
flight (:func:`wait_for_compiles`) rather than tearing numba down under it.
"""

import atexit
import sys
import threading
import traceback
from typing import Callable, List, Optional

from conveyor_twin.cell.model import Cell
from conveyor_twin.testing.errors import TwinTimeoutError

#: Longest wait for the kernels to compile (or load) before a twin starts [s].
COMPILE_BUDGET = 1800.0
#: A wait for the kernels longer than this is announced on stderr [s].
NOTICE_AFTER = 1.0
#: Longest wait at interpreter exit for a compile in flight [s].
EXIT_BUDGET = 600.0
_exit_hook = threading.Lock()
_exit_registered: List[bool] = []


def _warm(cell: Cell, seed: int) -> None:
    from conveyor_twin.coord.warmup import warm_up
    warm_up(cell, seed)


def ready_kernels(cell: Cell, seed: int, *, timeout: float,
                  warm: Optional[Callable[[Cell, int], None]] = None) -> None:
    """Compile or load every per-step kernel of ``cell``; return when done.

    :param cell: the twin's cell. :param seed: its seed.
    :param timeout: the harness's step timeout [s] (named in the notice; not used as a limit)
    :param warm: what does it (default: a warm-up on a scratch twin)
    :raises TwinTimeoutError: when it takes longer than :data:`COMPILE_BUDGET` (the compile
        goes on; the process waits for it at exit)
    :raises Exception: what the warm-up raised
    """
    _register_exit_wait()
    failure: List[BaseException] = []
    work = warm or _warm

    def run() -> None:
        try:
            work(cell, seed)
        except BaseException as exc:  # handed to the waiting caller, or printed if it left
            failure.append(exc)
            if not waiting.is_set():
                print('conveyor_twin: the kernel warm-up failed after the harness stopped '
                      'waiting for it:\n' + ''.join(traceback.format_exception(exc)),
                      file=sys.stderr, flush=True)

    waiting = threading.Event()
    waiting.set()
    thread = threading.Thread(target=run, name='conveyor_twin-kernels', daemon=False)
    thread.start()
    thread.join(NOTICE_AFTER)
    if thread.is_alive():
        print(f'conveyor_twin: compiling the simulation kernels (or loading them from the '
              f'cache) before the twin starts: up to {COMPILE_BUDGET:g} s, not counted against '
              f'the step timeout of {timeout:g} s ...', file=sys.stderr, flush=True)
        thread.join(COMPILE_BUDGET)
    if thread.is_alive():
        waiting.clear()
        raise TwinTimeoutError(
            f'the simulation kernels did not finish compiling within {COMPILE_BUDGET:g} s '
            f'(conveyor_twin.testing.kernels.COMPILE_BUDGET); the compile goes on and the '
            f'process waits for it at exit; `conveyor-twin warm-up` compiles them ahead')
    if failure:
        raise failure[0]


def wait_for_compiles(budget: float = EXIT_BUDGET) -> bool:
    """Wait until no numba compile runs in any thread (numba's compiler lock is free), at most
    ``budget`` [s]; return True if none runs. Called at interpreter exit."""
    module = sys.modules.get('numba.core.compiler_lock')  # not imported: nothing compiles
    lock = getattr(getattr(module, 'global_compiler_lock', None), '_lock', None)
    if lock is None:  # (or numba's internals changed: nothing to wait on)
        return True
    if not lock.acquire(blocking=False):
        print('conveyor_twin: waiting for a kernel compile in flight to finish before exit ...',
              file=sys.stderr, flush=True)
        if not lock.acquire(timeout=budget):
            print(f'conveyor_twin: a kernel compile still runs after {budget:g} s; exiting '
                  'anyway', file=sys.stderr, flush=True)
            return False
    lock.release()
    return True


def _register_exit_wait() -> None:
    with _exit_hook:
        if not _exit_registered:
            atexit.register(wait_for_compiles)
            _exit_registered.append(True)
