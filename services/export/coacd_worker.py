"""CoACD in a process of its own, so the export can bound its CPU time (run by path, see ``collision.py``).

CoACD's C++ search cannot be interrupted from Python; in a child process a CPU-time limit (``RLIMIT_CPU``,
set by the parent) ends it, and the export falls back to the parts it already has. The child imports only
numpy and coacd (not the ``services`` packages: no Open3D, no SciPy), so it starts in well under a second.

Protocol: an ``.npz`` on stdin with ``vertices``, ``triangles``, ``params`` (JSON text of CoACD's keyword
arguments) and ``cpu_budget_s`` (the child limits itself: no ``preexec_fn``, which is unsafe in a parent
with threads); an ``.npz`` on stdout with ``p0``, ``p1``, ... (each part's vertices).
"""

from __future__ import annotations

import io
import json
import math
import resource
import sys

import numpy as np


def main() -> None:
    with np.load(io.BytesIO(sys.stdin.buffer.read())) as z:
        vertices, triangles, params = z["vertices"], z["triangles"], json.loads(str(z["params"]))
        budget = float(z["cpu_budget_s"])
    soft = max(1, math.ceil(budget))
    resource.setrlimit(resource.RLIMIT_CPU, (soft, soft + 2))  # SIGXCPU ends the process past the budget
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(np.ascontiguousarray(vertices, dtype=np.float64),
                                       np.ascontiguousarray(triangles, dtype=np.int32)), **params)
    buf = io.BytesIO()
    np.savez(buf, **{f"p{i}": np.asarray(pv, dtype=np.float64) for i, (pv, _) in enumerate(parts)})
    sys.stdout.buffer.write(buf.getvalue())


if __name__ == "__main__":
    main()
