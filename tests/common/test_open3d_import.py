"""Open3D's browser viewer (Plotly, Dash) is not imported with Open3D, and still works when called."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.timeout(120)


def _run(code: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=100)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_registration_imports_open3d_without_plotly_or_dash():
    out = _run("import json, sys\n"
               "import services.registration.cloud\n"
               "print(json.dumps({'open3d': 'open3d' in sys.modules,"
               " 'viewer': sorted(m for m in ('dash', 'plotly', 'IPython') if m in sys.modules)}))")
    assert out == {"open3d": True, "viewer": []}


def test_plotly_drawing_still_loads_on_first_use():
    out = _run("import json, sys\n"
               "import common\n"
               "import numpy as np\n"
               "import open3d as o3d\n"
               "cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.eye(3)))\n"
               "fig = o3d.visualization.get_plotly_fig([cloud])\n"
               "module = sys.modules['open3d.visualization.draw_plotly']\n"
               "print(json.dumps({'figure': type(fig).__name__, 'points': len(fig.data[0].x),"
               " 'real': not getattr(module, '__objscan_deferred__', False), 'dash': 'dash' in sys.modules}))")
    assert out == {"figure": "Figure", "points": 3, "real": True, "dash": True}


def test_too_late_when_open3d_is_imported_already():
    out = _run("import json, sys\n"
               "import open3d\n"
               "from common.open3d_import import defer_plotly_drawing\n"
               "print(json.dumps({'deferred': defer_plotly_drawing(), 'dash': 'dash' in sys.modules}))")
    assert out == {"deferred": False, "dash": True}
