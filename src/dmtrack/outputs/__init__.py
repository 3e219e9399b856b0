"""dmtrack.outputs: the sinks that receive the odometry's results (DSO's ``Output3DWrapper`` idea).

The odometry only knows the :class:`~dmtrack.odometry.sink.OutputSink` protocol (``on_frame``, ``on_keyframe``,
``on_lost``, ``close``) and the :class:`~dmtrack.odometry.sink.KeyframeSnapshot` it hands out; everything that
turns those calls into something — files, memory, a viewer — lives here, above the odometry:

* :class:`RunDirectorySink` (:mod:`dmtrack.outputs.run_directory`): the files of ``dmtrack run``;
* :class:`MemorySink`, :class:`MultiSink` (:mod:`dmtrack.outputs.memory`): record calls; fan out to several sinks;
* :class:`RerunSink` (:mod:`dmtrack.outputs.rerun_sink`): the live view in the Rerun viewer or an .rrd file
  (``dmtrack run --viewer / --rrd``; rerun-sdk is imported only when one is made), and
  :mod:`dmtrack.outputs.rerun_view`, a finished run folder in the viewer (``dmtrack view``).

A new sink is any class with those four methods (and, for a viewer, the optional ``on_frame_info``); pass it to
:func:`dmtrack.track` (``sink=``) or :class:`~dmtrack.odometry.vo.VisualOdometry`.
"""

from dmtrack.outputs.memory import MemorySink, MultiSink
from dmtrack.outputs.rerun_sink import RerunSink
from dmtrack.outputs.run_directory import RunDirectorySink

__all__ = ["MemorySink", "MultiSink", "RerunSink", "RunDirectorySink"]
