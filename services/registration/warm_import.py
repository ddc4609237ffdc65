"""Import modules in a background thread while other work runs, and account for its CPU.

Why: ``objscan reconstruct`` runs the static stage first and the dynamic stage after it, and the dynamic
stage's modules (scikit-learn and the parts of SciPy it pulls in) cost ~1.5 CPU-s to import: half of the
command's start-up, paid on one core while the other waits. Imported in a thread during the static stage they
cost the same CPU but no start-up wall. The import is only a warm-up: the caller still imports normally where
it needs the modules (waiting on Python's per-module import lock if the warm-up is mid-way), so a warm-up that
fails changes nothing but the time.
"""

from __future__ import annotations

import importlib
import threading
import time


class WarmImport:
    """``modules`` imported in a daemon thread started now; ``cpu_s()`` is the thread's CPU once it is done."""

    def __init__(self, modules: tuple[str, ...]) -> None:
        self.modules = modules
        self._cpu = 0.0
        self._thread = threading.Thread(target=self._run, name="warm-import", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        t0 = time.thread_time()
        try:
            for name in self.modules:
                importlib.import_module(name)
        except Exception:  # noqa: BLE001 - a warm-up only: the real import raises where the module is used
            pass
        finally:
            self._cpu = time.thread_time() - t0

    def cpu_s(self) -> float:
        """The warm-up's CPU seconds (waits for it to finish: the caller is about to need the modules anyway)."""
        self._thread.join()
        return self._cpu
