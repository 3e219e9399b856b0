"""The starts of one run: a :class:`~dmtrack.initialization.initializer.GeometricInitializer` per distinct start
configuration among the run's odometry configurations (``init="geometric"``), fed the run's first frames.

:func:`dmtrack.track` reads the first frames once, feeds them here until every start has accepted or refused,
keeps them, and then gives them to the odometries as usual; the odometry of a configuration whose start accepted
begins with its map, one whose start refused begins from LSD-SLAM's random map (:meth:`RunStart.config_for`) and
``metrics.json`` says so (:meth:`RunStart.metrics`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from dmtrack.geometry.camera import PinholeCamera
from dmtrack.initialization.initializer import GeometricInitializer
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.initial_map import InitialMap

__all__ = ["RunStart"]


def _key(config: VOConfig) -> tuple[Any, ...]:
    """What a geometric start depends on (not the seed, the feature or the keyframe policy)."""
    return (config.initializer, config.depth, config.tracker, config.pyramid_levels)


class RunStart:
    """The geometric starts of a run's configurations.

    Parameters
    ----------
    camera : PinholeCamera
        The odometry's (cropped) camera.
    configs : list of VOConfig
        The run's configurations; those with ``init="geometric"`` get a start (shared when they agree on it).
    parallel : bool
        Multi-threaded kernels for the first maps.
    """

    def __init__(self, camera: PinholeCamera, configs: list[VOConfig], *, parallel: bool = False) -> None:
        self.configs = list(configs)
        self._starts: dict[tuple[Any, ...], GeometricInitializer] = {}
        for c in configs:
            if c.init == "geometric" and _key(c) not in self._starts:
                self._starts[_key(c)] = GeometricInitializer(camera, c, parallel=parallel)

    @property
    def collecting(self) -> bool:
        """Whether a start still wants frames."""
        return any(not s.done for s in self._starts.values())

    def add(self, index: int, timestamp: float, image: np.ndarray) -> bool:
        """Give the next frame to every start still collecting; return :attr:`collecting`."""
        for s in self._starts.values():
            if not s.done:
                s.add(index, timestamp, image)
        return self.collecting

    def end(self, frames: int) -> None:
        """The run has no more frames (``frames`` were given): the starts still collecting refuse."""
        for s in self._starts.values():
            if not s.done:
                s.refuse(f"the run ended after {frames} frames, before the start had seen enough motion: "
                          f"{s.motion_summary()}")

    def initial_map(self, config: VOConfig) -> InitialMap | None:
        """The first map of ``config``'s start (None: not geometric, or refused)."""
        s = self._starts.get(_key(config)) if config.init == "geometric" else None
        return None if s is None else s.initial_map

    def release_maps(self) -> None:
        """The odometries have copied their first maps: drop the starts' arrays (six 640×480 maps, 6 MB); the
        accepted frame and the start's measurements stay for :meth:`metrics`."""
        empty = np.zeros((0, 0), np.float32)
        for s in self._starts.values():
            m = s.initial_map
            if m is not None and m.idepth.size:
                s.initial_map = dataclasses.replace(m, valid=empty.astype(bool), idepth=empty, idepth_var=empty,
                                                    idepth_smoothed=empty, idepth_var_smoothed=empty,
                                                    validity=empty)  # fmt: skip

    def config_for(self, config: VOConfig) -> VOConfig:
        """The configuration the odometry runs with: ``init="random"`` where the geometric start refused."""
        if config.init == "geometric" and self.initial_map(config) is None:
            return dataclasses.replace(config, init="random")
        return config

    def refusal(self, config: VOConfig) -> str | None:
        """Why ``config``'s geometric start refused (None if it did not)."""
        s = self._starts.get(_key(config)) if config.init == "geometric" else None
        return None if s is None else s.reason

    def metrics(self, config: VOConfig) -> dict[str, Any]:
        """``metrics.json``'s start keys: ``init``, ``init_accepted_frame``, ``init_refused``, ``init_fallback``,
        ``init_s`` and ``init_info`` (what the start measured)."""
        s = self._starts.get(_key(config)) if config.init == "geometric" else None
        if s is None:
            return {"init": config.init, "init_accepted_frame": None, "init_refused": None, "init_fallback": None}
        m = s.initial_map
        return {
            "init": config.init,
            "init_accepted_frame": None if m is None else int(m.accepted_frame),
            "init_refused": s.reason,
            "init_fallback": "random" if m is None else None,
            "init_s": float(s.info.get("seconds", 0.0)),
            "init_info": {k: v for k, v in s.info.items() if k != "refused"},
        }
