"""What the reports of ``blendtrack compare`` and ``blendtrack batch`` share:
the mean with its 95 % Student-t confidence interval (scipy), how a number
is printed, figures written to files, and HTML pages from the package's jinja2 templates
(``blendtrack/templates/``), self-contained (images embedded)."""

from __future__ import annotations

import base64
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np


def mean_ci(values: Sequence[float], confidence: float = 0.95) -> tuple[float, float, float]:
    """Mean and two-sided ``confidence`` Student-t interval of the values
    (NaN values left out; NaN bounds with fewer than 2 values)."""
    from scipy.stats import t  # type: ignore[import-untyped]

    x = np.array([v for v in values if v == v], dtype=float)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    m = float(x.mean())
    if len(x) < 2:
        return m, math.nan, math.nan
    q = float(t.ppf(0.5 + 0.5 * confidence, len(x) - 1))
    half = q * float(x.std(ddof=1)) / math.sqrt(len(x))
    return m, m - half, m + half


def fmt(x: float) -> str:
    """How report.md prints a number (tests parse it back)."""
    if not isinstance(x, (int, float)) or not math.isfinite(x):
        return "n/a"
    return f"{x:.4g}"


def save_figure(fig: Any, file: Path, dpi: int) -> Path:
    """Lays out, writes and closes a matplotlib figure; returns its file."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(file, dpi=dpi)
    plt.close(fig)
    return file


def png_data_uri(file: Path) -> str:
    """A PNG file as a ``data:`` URI, to embed in a page."""
    return "data:image/png;base64," + base64.b64encode(file.read_bytes()).decode()


def render_html(template: str, **context: Any) -> str:
    """The package template ``templates/<template>`` rendered with
    ``context`` (HTML-escaped; ``fmt`` and ``png_data_uri`` available as filters)."""
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.PackageLoader("blendtrack", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
    )
    env.filters["fmt"] = fmt
    env.filters["png_data_uri"] = png_data_uri
    return env.get_template(template).render(**context)
