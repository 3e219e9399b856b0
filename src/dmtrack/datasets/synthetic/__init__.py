"""A deterministic synthetic sequence: a textured room rendered by ray casting, with exact depth and poses.

* :mod:`~dmtrack.datasets.synthetic.scene` — the room, its boxes and slanted planes, and their mip-mapped
  procedural textures (:class:`Scene`, :func:`make_scene`).
* :mod:`~dmtrack.datasets.synthetic.renderer` — ray casting of a scene from a pinhole camera: the numba
  kernel (:func:`render`), its plain numpy reference (:func:`render_numpy`) and :func:`world_points`.
* :mod:`~dmtrack.datasets.synthetic.sequence` — the smooth 6-DoF trajectory (:func:`make_trajectory`), the
  photometric disturbances and :class:`SyntheticSequence` with its :class:`SyntheticConfig`.

World frame: metres, ``z`` up, the floor at ``z = 0``, the room centred on the ``z`` axis.
"""

from dmtrack.datasets.synthetic.renderer import render, render_numpy, world_points
from dmtrack.datasets.synthetic.scene import Scene, make_scene
from dmtrack.datasets.synthetic.sequence import SyntheticConfig, SyntheticSequence, make_trajectory

__all__ = [
    "Scene",
    "SyntheticConfig",
    "SyntheticSequence",
    "make_scene",
    "make_trajectory",
    "render",
    "render_numpy",
    "world_points",
]
