"""A Q-table drawn on its grid world: the colour of a cell is the state value max_a Q(s, a), the arrow is the greedy
action, a dot marks a state whose actions are all still tied (never updated), and holes, cliff cells and the goal
are grey. Optionally, the path a greedy policy walks (:func:`rlbook.tabular_seeds.greedy_path`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rlcore.tabular import grid_map

MOVES = {"FrozenLake-v1": [(0, -1), (1, 0), (0, 1), (-1, 0)],        # 0 left, 1 down, 2 right, 3 up
         "CliffWalking-v1": [(-1, 0), (0, 1), (1, 0), (0, -1)]}      # 0 up, 1 right, 2 down, 3 left
"""The (row, column) displacement of each action, per grid world."""

LABELS = {"H": "hole", "C": "cliff", "G": "goal"}
"""The cells drawn in grey, by their letter in :func:`rlcore.tabular.grid_map`."""


# [plot-table]
def plot_table(ax, Q: np.ndarray, env_id: str, title: str, path: list[int] | None = None,
               vmin: float | None = None, vmax: float | None = None, **env_kwargs: Any):
    """Heatmap of max_a Q(s, a) with greedy arrows, on the task's grid; returns the image (for a colour bar)."""
    from matplotlib.patches import Rectangle

    grid = grid_map(env_id, **env_kwargs)
    n_cols = grid.shape[1]
    special = np.isin(grid, list(LABELS))
    V = Q.max(axis=1).reshape(grid.shape)
    image = ax.imshow(np.ma.masked_where(special, V), cmap="viridis", vmin=vmin, vmax=vmax)
    if path is not None:
        rows, cols = np.unravel_index(path, grid.shape)
        ax.plot(cols, rows, color="tab:red", lw=4, alpha=0.85, solid_capstyle="round")
        ax.set_xlabel("red: the greedy path", fontsize=9)
    for (row, col), letter in np.ndenumerate(grid):
        if letter in LABELS:
            ax.add_patch(Rectangle((col - 0.5, row - 0.5), 1, 1, color="0.55"))
            ax.text(col, row, LABELS[letter], ha="center", va="center", color="white", fontsize=8)
            continue
        r, g, b, _ = image.cmap(image.norm(V[row, col]))
        ink = "black" if 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "white"   # readable on the cell's colour
        q = Q[row * n_cols + col]
        if np.all(q == q[0]):
            ax.plot(col, row, "o", color=ink, markersize=3)
        else:
            d_row, d_col = MOVES[env_id][int(q.argmax())]
            ax.annotate("", xy=(col + 0.35 * d_col, row + 0.35 * d_row),
                        xytext=(col - 0.35 * d_col, row - 0.35 * d_row),
                        arrowprops=dict(arrowstyle="-|>", color=ink, lw=1.5))
        if letter == "S":
            ax.text(col - 0.45, row - 0.3, "start", color=ink, fontsize=7)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=10)
    return image
# [/plot-table]
