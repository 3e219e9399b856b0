"""dmtrack.outputs: the sinks that receive the odometry's results (DSO's ``Output3DWrapper`` idea).

The odometry only knows the :class:`~dmtrack.odometry.sink.OutputSink` protocol (``on_frame``, ``on_keyframe``,
``on_lost``, ``close``) and the :class:`~dmtrack.odometry.sink.KeyframeSnapshot` it hands out; everything that
turns those calls into something — files, memory, later a viewer — lives here, above the odometry:

* :class:`RunDirectorySink` (:mod:`dmtrack.outputs.run_directory`): the files of ``dmtrack run``;
* :class:`MemorySink`, :class:`MultiSink` (:mod:`dmtrack.outputs.memory`): record calls; fan out to several sinks.

A new sink is any class with those four methods; pass it to :func:`dmtrack.track` (``sink=``) or
:class:`~dmtrack.odometry.vo.VisualOdometry`.
"""

from dmtrack.outputs.memory import MemorySink, MultiSink
from dmtrack.outputs.run_directory import RunDirectorySink

__all__ = ["MemorySink", "MultiSink", "RunDirectorySink"]
