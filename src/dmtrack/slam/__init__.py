"""SLAM above the odometry (issue 31): a keyframe graph with Sim(3) constraints, optimised by gtsam.

The odometry never imports this package. What exists so far:

- :mod:`~dmtrack.slam.pose_graph`: the Sim(3) pose graph (keyframes, relative-pose edges with their information)
  and its optimisation by gtsam's Levenberg–Marquardt (``pip install 'dmtrack[slam]'``).

Not built yet: the Sim(3) direct alignment between keyframes on the N-channel maps, the candidate search, the
reciprocal check, and ``dmtrack run --slam``.
"""

from __future__ import annotations
