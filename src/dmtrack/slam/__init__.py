"""SLAM above the odometry (issue 31, ``dmtrack run --slam``, docs/slam.md): a keyframe graph with Sim(3)
constraints, optimised by gtsam.

The odometry never imports this package, and this package imports no viewer or file writer:

- :mod:`~dmtrack.slam.sim3_tracker`: Sim(3) direct alignment of two keyframes on the N-channel maps;
- :mod:`~dmtrack.slam.constraints`: LSD-SLAM's reciprocal test; :mod:`~dmtrack.slam.candidates`: loop candidates;
- :mod:`~dmtrack.slam.pose_graph`: the Sim(3) pose graph and its optimisation by gtsam
  (``pip install 'dmtrack[slam]'``);
- :mod:`~dmtrack.slam.backend`: the back end, a sink of the odometry on its own thread;
- :mod:`~dmtrack.slam.listener`: what a viewer implements to be told of each optimisation.
"""

from __future__ import annotations
