"""PNG figures for people: error maps, zoomed crops, PSNR curves (matplotlib, Agg)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ..io.images import atomic_path


def _save(fig, path):
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)
    return path


def display(image: np.ndarray) -> np.ndarray:
    """Linear camera RGB -> something viewable: scaled to the 99.5th percentile, gamma 1/2.2."""
    scale = max(float(np.percentile(image, 99.5)), 1e-6)
    return np.clip(image / scale, 0, 1) ** (1 / 2.2)


def error_maps(truth: np.ndarray, estimates: dict, path, title: str):
    """One row per method: the image and |error| averaged over channels (paper, Figs 6-7)."""
    names = list(estimates)
    fig, axes = plt.subplots(len(names) + 1, 2, figsize=(7, 3.2 * (len(names) + 1)), squeeze=False)
    vmax = max(float(np.abs(est - truth).mean(axis=-1).max()) for est in estimates.values()) or 1.0
    axes[0, 0].imshow(display(truth))
    axes[0, 0].set_title("ground truth")
    axes[0, 1].axis("off")
    for row, name in enumerate(names, start=1):
        axes[row, 0].imshow(display(estimates[name]))
        axes[row, 0].set_title(name)
        im = axes[row, 1].imshow(np.abs(estimates[name] - truth).mean(axis=-1), cmap="inferno", vmin=0, vmax=vmax)
        axes[row, 1].set_title(f"|error| {name}")
        fig.colorbar(im, ax=axes[row, 1], fraction=0.046)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    return _save(fig, path)


def zoomed_crops(truth: np.ndarray, estimates: dict, box, path, title: str):
    """The same crop of the truth and of every method, side by side (paper, Figs 8-9)."""
    r0, r1, c0, c1 = box
    panels = {"ground truth": truth, **estimates}
    fig, axes = plt.subplots(1, len(panels), figsize=(2.6 * len(panels), 2.9), squeeze=False)
    scale = max(float(np.percentile(truth, 99.5)), 1e-6)
    for ax, (name, image) in zip(axes[0], panels.items()):
        ax.imshow(np.clip(image[r0:r1, c0:c1] / scale, 0, 1) ** (1 / 2.2), interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    return _save(fig, path)


def psnr_curves(x_values, series: dict, path, xlabel: str, ylabel: str, title: str, logx: bool = True):
    """PSNR against illumination or run time, one line per method (paper, Fig. 10)."""
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, ys in series.items():
        ax.plot(x_values if not isinstance(x_values, dict) else x_values[name], ys, marker="o", label=name)
    if logx:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return _save(fig, path)


def gradient_images(images: dict, path, title: str):
    """|gradient| of the centre view along each dim (paper, Fig. 5)."""
    fig, axes = plt.subplots(1, len(images), figsize=(2.8 * len(images), 3), squeeze=False)
    vmax = max(float(np.percentile(img, 99.5)) for img in images.values()) or 1.0
    for ax, (name, image) in zip(axes[0], images.items()):
        ax.imshow(image, cmap="gray", vmin=0, vmax=vmax)
        ax.set_title(name)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    return _save(fig, path)
