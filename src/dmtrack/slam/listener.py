"""Who hears of the graph's optimisations: the :class:`GraphListener` protocol and the :class:`OptimisedGraph` it
receives (DSO's ``Output3DWrapper`` idea, for the back end).

The back end knows no viewer. After each optimisation of the pose graph,
:class:`~dmtrack.slam.backend.SlamBackend` hands every listener an :class:`OptimisedGraph` — the keyframes'
optimised poses and the accepted edges — on the thread that optimised: the back end's own thread while the run goes
on, the caller's for the final optimisation when the run ends. A listener must be quick (the back end waits for
it) and must not keep the arrays it is given beyond the call without copying them. An exception of a listener
never stops the back end: the listener is dropped and the error kept in
:attr:`~dmtrack.slam.backend.SlamBackend.listener_errors`.

A listener is any object with ``on_graph_optimised(graph)``; :func:`graph_listeners` finds them among a run's
sinks (and inside fan-out sinks, which keep theirs in ``sinks``), so that the Rerun viewer, an odometry sink, is
also told of the graph.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class OptimisedGraph:
    """The keyframe graph just after an optimisation.

    ``keyframe_ids``, ``frame_indices``, ``timestamps`` ``(n,)`` in keyframe order; ``poses`` ``(n, 4, 4)`` the
    keyframes' optimised camera-to-world poses as SE(3) (the Sim(3) scale dropped, as ``keyframes.txt``),
    ``scales`` ``(n,)`` their Sim(3) scales; ``edges`` the accepted edges ``(i, j, kind)`` between keyframe ids,
    kind ``"odometry"`` or ``"loop"`` (an accepted loop pair once); ``optimisation`` counts the optimisations so
    far (1 for the first); ``final``: the run's last one.
    """

    keyframe_ids: np.ndarray
    frame_indices: np.ndarray
    timestamps: np.ndarray
    poses: np.ndarray
    scales: np.ndarray
    edges: tuple[tuple[int, int, str], ...]
    optimisation: int
    final: bool = False

    @property
    def positions(self) -> np.ndarray:
        """``(n, 3)`` the keyframes' optimised camera centres."""
        return self.poses[:, :3, 3]

    def segments(self, kind: str) -> np.ndarray:
        """``(m, 2, 3)`` the end points of the accepted edges of ``kind`` (both ends in the graph)."""
        row = {int(k): r for r, k in enumerate(self.keyframe_ids)}
        pairs = [(row[i], row[j]) for i, j, k in self.edges if k == kind and i in row and j in row]
        if not pairs:
            return np.zeros((0, 2, 3))
        return self.positions[np.array(pairs)]


@runtime_checkable
class GraphListener(Protocol):
    """Told of every optimisation of the keyframe graph (see the module docstring)."""

    def on_graph_optimised(self, graph: OptimisedGraph) -> None: ...


def graph_listeners(*sinks: Any) -> list[GraphListener]:
    """The objects among ``sinks`` (``None`` skipped), and inside fan-out sinks (their ``sinks``), that have
    ``on_graph_optimised``; each once, in order."""
    found: list[Any] = []

    def walk(items: Iterable[Any]) -> None:
        for s in items:
            if s is None or any(s is f for f in found):
                continue
            if callable(getattr(s, "on_graph_optimised", None)):
                found.append(s)
            children = getattr(s, "sinks", None)
            if isinstance(children, (list, tuple)):
                walk(children)

    walk(sinks)
    return found
