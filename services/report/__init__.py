"""The visual session report: ``build_report(session_dir, out)`` writes one self-contained HTML page.

See docs/report.md. Rendering is CPU-only (``raster.render_points``), so it works without a display.
"""

from services.report.build import ReportConfig, build_report, render_html
from services.report.errors import ReportError
from services.report.raster import RasterCamera, colormap, orbit_camera, render_points
from services.report.session_data import SessionData, load_session

__all__ = ["RasterCamera", "ReportConfig", "ReportError", "SessionData", "build_report", "colormap", "load_session",
           "orbit_camera", "render_html", "render_points"]
