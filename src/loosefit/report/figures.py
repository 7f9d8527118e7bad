"""The report's figures: error over time (matplotlib) and error maps on the garment (offscreen render
through :mod:`loosefit.viz`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.paths import atomic_path


def rmse_per_frame_mm(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-frame RMSE ``(T,)`` in millimetres of ``pred``/``gt (T, V, 3)`` metres."""
    return 1000.0 * np.sqrt(np.mean(np.sum((pred - gt) ** 2, axis=-1), axis=-1))


def error_over_time_png(path: str | Path, title: str, series: dict[str, np.ndarray], fps: float) -> Path:
    """A line plot of per-frame RMSE ``{label: (T,) mm}`` against time (s), written to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 3.2), dpi=100)
    try:
        for label, values in series.items():
            ax.plot(np.arange(len(values)) / fps, values, label=label, linewidth=1.4)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("RMSE (mm)")
        ax.set_title(title, fontsize=10)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
        fig.tight_layout()
        path = Path(path)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
    return path


def error_map_png(path: str | Path, gt: np.ndarray, faces: np.ndarray, body_verts: np.ndarray, body_faces: np.ndarray,
                  predictions: dict[str, np.ndarray], frame: int, size: tuple[int, int] = (320, 400)) -> tuple[Path, float]:
    """One frame side by side: the simulation, then each prediction coloured by its per-vertex error (mm,
    one colour scale for all: 0 to the largest 95th percentile); the posed body in each panel.

    Args:
        gt: ``(T, V, 3)``; predictions: ``{label: (T, V, 3)}``; body_verts: ``(T, Vb, 3)``.

    Returns:
        The PNG path and the colour scale's top in mm.
    """
    from loosefit.viz.render import render_frames
    from loosefit.viz.scene import BODY_COLOR, MeshTrack
    from loosefit.viz.writers import save_png

    errors = {m: 1000.0 * np.linalg.norm(p - gt, axis=-1) for m, p in predictions.items()}
    top = max(1e-3, max(float(np.percentile(e, 95)) for e in errors.values()))
    sl = slice(frame, frame + 1)

    def panel(verts, label, scalars=None):
        body = MeshTrack(body_verts[sl], body_faces, color=BODY_COLOR, label="body")
        garment = MeshTrack(verts[sl], faces, scalars=None if scalars is None else scalars[sl], cmap="inferno",
                            clim=(0.0, top), label=label, scalar_name="error (mm)")
        return [body, garment]

    panels = [panel(gt, "simulation")] + [panel(predictions[m], m, errors[m]) for m in predictions]
    titles = ["simulation"] + list(predictions)
    image = render_frames(panels, size=size, frames=[0], titles=titles)[0]
    return save_png(Path(path), image), top
