"""objscan's services and the CLI."""

from common.open3d_import import defer_plotly_drawing

defer_plotly_drawing()  # before any module imports Open3D: its browser viewer loads only when used
