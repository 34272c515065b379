"""Saving matplotlib figures as PNG files, the same way for every plot of the package."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:       # the numerical core loads without matplotlib
    from matplotlib.figure import Figure


def save_figure(fig: Figure, path: str | Path, tight: bool = True) -> Path:
    """
    Write ``fig`` as a PNG (110 dpi) to ``path``, creating folders, and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path
        Target file.
    tight : bool
        Apply ``tight_layout`` first.

    Returns
    -------
    Path
        The written file.
    """
    import matplotlib.pyplot as plt  # imported here: the numerical core loads without it
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
