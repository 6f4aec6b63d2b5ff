"""Rerun recordings (.rrd) of a run: scene photo and map, agents, trails, predictions, anchors, ego, metrics.

One recording per run, on a dedicated ``rr.RecordingStream`` (several loggers can write at once).
Timelines: ``step`` (sequence) and ``time`` (seconds, step * 0.4). Entities, all positions in world metres:

    world                        static flip of the y axis, so the default view (origin "/") shows y up
    world/scene                  static transform raster pixels -> world metres (see ``scene_raster``)
    world/scene/photo            static Image, the scene photo
    world/scene/walkable         static SegmentationImage: 0 walkable (clear), 1 blocked (red), 2 off the photo
    world/agents                 Points2D, labels = agent ids
    world/trails                 LineStrips2D, each agent's recent history
    world/predictions/<agent>    LineStrips2D, S predicted futures of one agent
    world/anchors/prototype      LineStrips2D, anchors before adaptation (M agents x S strips)
    world/anchors/adapted        LineStrips2D, anchors after adaptation to the map
    world/ego, world/ego/goal    Points2D, the ego robot and its goal
    world/ego/heading            Arrows2D, the way the robot faces (``ego_heading``), one body radius long
    world/truth, world/detections  Points2D, with a sensor (not the oracle): every true person, and what the sensor
                                 detected this step (the agents and their forecasts are then the tracker's tracks)
    world/walls                  static LineStrips2D, wall segments (``log_walls``)
    world/events/<name>          Points2D from the step of an event on, labelled (``log_marker``: a collision)
    metrics/<unit>/<name>        Scalars; <unit> is ``metric_unit(name)``: reward, metres, share or count
    notes                        static TextDocument (markdown), shown beside the plots (``notes=``)

Entities logged at one step and absent from the next are cleared, so agents that left the scene do not
linger in the viewer. Colours follow ``st_sim.plot.agent_colors``.

The default blueprint puts the world view on the left and one time-series view per unit on the right
(``METRIC_VIEWS``): the reward, distances in metres (ADE, FDE, the closest pedestrian), shares in [0, 1] (map
violation) and counts (matured predictions, collisions), so a metric of 0.05 is never drawn flat on the
scale of a reward of 15.

Files (``st_sim.rerun_file``): ``checked_recording_target`` expands ``~`` and refuses a target that cannot be
written, naming it. A recording is written in place under its final name and flushed at least every
``FLUSH_EVERY_S``, so a run that is interrupted, garbage-collected without ``close`` or even killed leaves a
readable file. A write that fails (disk full, file-size limit) raises ``RecordingWriteError`` naming the file,
from ``log_step`` or ``close``; the file is cut back to what the last complete flush wrote (or removed if
nothing was). A finished recording is never overwritten: if the path exists, the next free
``<stem>-<n><suffix>`` is used (``RerunLogger.path`` says which). Two live writers to one path are refused.

Memory: recordings are written without Rerun's footer, a manifest of every chunk that Rerun's file sink keeps
in memory until the end of the recording, so a recording of any length holds only the data of one flush
(``NEVER_S``: the batcher never flushes on its own). Rerun reads such files by scanning them; ``rerun rrd
optimize`` adds the footer afterwards. The file sink's warning about the missing footer is silenced when this
module is the first to import Rerun and ``RUST_LOG`` is unset (its errors still print).

Placing the photo: Rerun's transforms are affine, the ETH/UCY homographies are not always. When an affine
map fits the homography to within ``PROJECTIVE_TOL_M`` over the whole photo (zara1, zara2, univ: exactly
affine) the photo is logged as is under that affine map. Otherwise (eth, hotel: clearly projective) photo
and map are warped with ``cv2.warpPerspective`` into a world-aligned raster of ``WARP_M_PER_PX`` metres per
pixel covering the photo's footprint, which is then placed with a scale and a translation.
"""

from __future__ import annotations

import os
import sys
import time
import weakref
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from replays.constants import STEP_S
from replays.errors import MemoryBudgetError
from replays.scenes import Scene
from st_sim.plot import ADAPTED_RGB, BLOCKED_TINT_RGB, GT_RGB, PROTOTYPE_RGB, agent_colors
from st_sim.rerun_file import (
    RecordingPathError,
    RecordingSink,
    RecordingWriteError,
    checked_recording_target,
    claim,
    new_file,
    unlock,
)

__all__ = ["METRIC_VIEWS", "RecordingPathError", "RecordingWriteError", "RerunLogger", "SceneRaster",
           "checked_recording_target", "metric_unit", "scene_raster"]

QUIET_FILE_SINK = "warn,re_log_encoding::rrd::file_sink=error"  # Rust log filter: no footer warning per file
try:
    if "rerun" not in sys.modules and "RUST_LOG" not in os.environ:
        os.environ["RUST_LOG"] = QUIET_FILE_SINK  # read once, when Rerun's bindings load
        try:
            import rerun as rr
        finally:
            del os.environ["RUST_LOG"]  # child processes see the user's environment
    import rerun as rr
    import rerun.blueprint as rrb
except ImportError as err:
    raise ImportError("st_sim.rerun_log needs the Rerun SDK: `pip install rerun-sdk`") from err

PROJECTIVE_TOL_M = 0.05  # largest affine-fit error [m] over the photo for which the photo is logged unwarped
WARP_M_PER_PX = 0.025  # resolution of the world-aligned raster of projective scenes [m per pixel]
MAX_RASTER_PX = 8000  # a raster side longer than this means a broken homography (<= 256 MB of raster)
FLUSH_EVERY_S = 1.0  # longest wall time between flushes of a file recording [s]
NEVER_S = 1e9  # batcher tick: the batcher never flushes on its own, only ``RecordingSink.flush`` [s]
NEVER_BYTES = 1 << 40  # batcher size threshold, likewise never reached [bytes]
AGENT_RADIUS_M = 0.25  # drawn radius of a pedestrian [m]
EGO_RADIUS_M = 0.4  # drawn radius of the ego robot [m]
TRAIL_RADIUS_M = 0.05  # half-width of history lines [m]
PATH_RADIUS_M = 0.025  # half-width of predicted futures and anchors [m]
PREDICTION_ALPHA = 110  # opacity (0-255) of predicted futures
WALKABLE, BLOCKED, OFF_PHOTO = 0, 1, 2  # classes of the logged walkability image
WALL_RGB = (60, 60, 60)  # colour of logged wall segments
WALL_RADIUS_M = 0.04  # half-width of logged wall segments [m]
MARKER_RADIUS_M = 0.5  # drawn radius of an event marker [m]


METRIC_VIEWS = {  # unit -> title of its time-series view
    "reward": "reward",
    "metres": "distance [m]: ADE, FDE, clearance",
    "share": "share [0-1]: map violation",
    "count": "count: matured predictions, collisions",
}
SHARE_NAMES = frozenset({"map_violation"})  # shares whose name does not end in _share or _rate


def metric_unit(name: str) -> str:
    """The unit group (a key of ``METRIC_VIEWS``) a metric is plotted in, from its name.

    ``reward...`` -> "reward"; a name ending in ``_m`` -> "metres"; ``_share``, ``_rate`` or one of
    ``SHARE_NAMES`` -> "share"; anything else (matured, ego_collisions) -> "count".
    """
    if name.startswith("reward"):
        return "reward"
    if name.endswith("_m"):
        return "metres"
    if name.endswith(("_share", "_rate")) or name in SHARE_NAMES:
        return "share"
    return "count"


@dataclass(frozen=True)
class SceneRaster:
    """Photo and walkability map on a common pixel grid placed in the world by an affine map."""

    photo: np.ndarray
    """(H, W, 3) uint8 RGB"""
    classes: np.ndarray
    """(H, W) uint8: WALKABLE, BLOCKED or OFF_PHOTO"""
    world_from_raster: np.ndarray
    """(3, 3) affine map from Rerun image coordinates (pixel (c, r) spans [c, c+1] x [r, r+1]) to metres"""
    warped: bool
    """True when the photo was resampled because the homography is projective"""


def scene_raster(scene: Scene) -> SceneRaster:
    """The scene's photo and map as Rerun logs them (see the module docstring for the choice).

    Raises:
        ValueError: the photo crosses the homography's horizon.
        MemoryBudgetError: a warped raster would have a side over ``MAX_RASTER_PX`` (8000 px, 256 MB of
            photo and classes); checked before anything is allocated.
    """
    height, width = scene.walkable.shape
    affine, error_m = _affine_fit(scene.H, width, height)
    classes = np.where(scene.walkable, WALKABLE, BLOCKED).astype(np.uint8)
    if error_m <= PROJECTIVE_TOL_M:
        centre_shift = np.array([[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]])  # image coord -> index
        return SceneRaster(scene.photo, classes, affine @ centre_shift, warped=False)
    corners_px = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], dtype=np.float64)
    if len(np.unique(np.sign(np.c_[corners_px, np.ones(4)] @ scene.H[2]))) != 1:
        raise ValueError(f"scene {scene.name}: the photo crosses the homography's horizon; it cannot be placed")
    corners_m = scene.pixel_to_world(corners_px)
    low_m = corners_m.min(axis=0)
    size_px = np.ceil((corners_m.max(axis=0) - low_m) / WARP_M_PER_PX).astype(int) + 1
    if size_px.max() > MAX_RASTER_PX:
        raise MemoryBudgetError(f"scene {scene.name}: photo covers {size_px * WARP_M_PER_PX} m, a raster of "
                                f"{size_px.tolist()} px at {WARP_M_PER_PX} m/px; at most {MAX_RASTER_PX} px a side")
    world_from_raster = np.array([[WARP_M_PER_PX, 0, low_m[0]], [0, WARP_M_PER_PX, low_m[1]], [0, 0, 1]])
    centre_shift = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])  # raster index -> image coord
    source_from_raster = scene.H_inv @ world_from_raster @ centre_shift  # raster index -> photo index
    size = (int(size_px[0]), int(size_px[1]))
    photo = cv2.warpPerspective(scene.photo, source_from_raster, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    classes = cv2.warpPerspective(classes, source_from_raster, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=OFF_PHOTO)
    return SceneRaster(photo, classes, world_from_raster, warped=True)


def _affine_fit(H: np.ndarray, width: int, height: int) -> tuple[np.ndarray, float]:
    """Least-squares affine approximation (3, 3) of a homography over a pixel grid, and its largest error [m]."""
    u, v = np.meshgrid(np.linspace(0, width - 1, 9), np.linspace(0, height - 1, 9))
    pixels = np.c_[u.ravel(), v.ravel(), np.ones(u.size)]  # (81, 3)
    mapped = pixels @ H.T
    world = mapped[:, :2] / mapped[:, 2:]
    coef, *_ = np.linalg.lstsq(pixels, world, rcond=None)  # (3, 2)
    error_m = float(np.linalg.norm(pixels @ coef - world, axis=1).max())
    return np.vstack([coef.T, [0.0, 0.0, 1.0]]), error_m


class RerunLogger:
    """Write one run to an .rrd file (or a spawned viewer), step by step.

    ::

        with RerunLogger("run.rrd", load_scene("zara1")) as log:
            for step in range(steps):
                log.log_step(step, positions_m, ids, trails=trails, predictions=futures, prediction_ids=ids,
                             metrics={"ade_m": ade})

    Args:
        target: path of the .rrd file to write (``~`` expanded; see "Files" in the module docstring), or
            "spawn" to open a viewer.
        scene: scene whose photo and walkability map are logged once, or None.
        app_id: Rerun application id.
        notes: markdown logged once as ``notes`` and shown above the plots (what the recording shows), or None.

    Attributes:
        path: the file being written (``target``, or a numbered sibling if it existed); None for "spawn".

    Raises:
        RecordingPathError: another live logger writes to ``target``, or it cannot be written (see
            ``checked_recording_target``).
        RecordingWriteError: the scene could not be written to the file.
    """

    def __init__(self, target: str | os.PathLike, scene: Scene | None, app_id: str = "stcrowd",
                 notes: str | None = None):
        target = checked_recording_target(target)
        batching = rr.ChunkBatcherConfig(flush_tick=NEVER_S, flush_num_bytes=NEVER_BYTES, flush_num_rows=NEVER_BYTES)
        recording = rr.RecordingStream(app_id, batcher_config=batching)
        recording.set_log_time_enabled(False)  # only the step and time timelines
        recording.set_log_tick_enabled(False)
        blueprint = _blueprint(scene, notes is not None)
        if target == "spawn":
            recording.spawn(default_blueprint=blueprint)
            self._sink = RecordingSink(recording)
        else:
            lock = claim(target)
            try:
                self._sink = RecordingSink(recording, new_file(target), lock, blueprint)
            except BaseException:
                unlock(lock)
                raise
        self.path: Path | None = self._sink.path
        # finishes the file and frees the lock on close(), garbage collection or interpreter exit
        self._finish = weakref.finalize(self, self._sink.finish)
        self._live: set[str] = set()  # per-step entities logged at the previous step
        self._rec = recording
        self._rec.log("world", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        if scene is not None:
            self._log_scene(scene)
        if notes is not None:
            self._rec.log("notes", rr.TextDocument(notes, media_type=rr.MediaType.MARKDOWN), static=True)
        self._sink.flush()

    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def close(self) -> None:
        """Flush and finish the file, free its path's lock; later calls do nothing.

        Raises:
            RecordingWriteError: the last steps could not be written (the file keeps the steps before them).
        """
        self._finish()

    def log_step(self, step: int, positions_m: np.ndarray, ids: np.ndarray, *,
                 trails: list[np.ndarray] | np.ndarray | None = None, trail_mask: np.ndarray | None = None,
                 predictions: np.ndarray | None = None, prediction_ids: np.ndarray | None = None,
                 ego_xy_m: np.ndarray | None = None, ego_goal_m: np.ndarray | None = None,
                 metrics: dict[str, float] | None = None, prototype_anchors: np.ndarray | None = None,
                 adapted_anchors: np.ndarray | None = None, ego_heading: np.ndarray | None = None,
                 truth_xy_m: np.ndarray | None = None, detections_xy_m: np.ndarray | None = None) -> None:
        """Log one step (0.4 s); entities not given now but logged at the previous step are cleared.

        Raises ``ValueError`` for a malformed argument, and ``RecordingWriteError`` (now and at every later
        call) once the file could not be written.

        Args:
            step: step index; ``time`` is step * 0.4 s.
            positions_m: (N, 2) agent positions, metres, world frame.
            ids: (N,) integer agent ids.
            trails: recent history per agent (same order as ``ids``): a list of N (T_i, 2) arrays, or an
                (N, T, 2) array whose missing points are NaN or False in ``trail_mask``; metres.
            trail_mask: (N, T) bool, True where the (N, T, 2) ``trails`` hold a point.
            predictions: (M, S, T_pred, 2) futures, metres, of the agents ``prediction_ids`` (M,).
            prediction_ids: (M,) integer ids of the predicted agents (also used by the anchors).
            ego_xy_m: (2,) ego position; ego_goal_m: (2,) its goal; metres.
            metrics: name -> value, logged as ``metrics/<unit>/<name>`` (unit: ``metric_unit(name)``).
            prototype_anchors: (M, S, T, 2) anchors before adaptation, metres, world frame.
            adapted_anchors: (M, S, T, 2) anchors after adaptation, metres, world frame.
            ego_heading: (2,) unit vector the ego faces (drawn with the ego).
            truth_xy_m: (K, 2) every true person, when the agents are what a sensor perceived [m].
            detections_xy_m: (D, 2) the sensor's detections of this step [m].
        """
        if self._sink.error is not None:
            raise self._sink.error
        self._rec.set_time("step", sequence=step)
        self._rec.set_time("time", duration=step * STEP_S)
        positions_m = _as_points(positions_m, "positions_m", (None, 2))
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if len(ids) != len(positions_m):
            raise ValueError(f"log_step: {len(ids)} ids for {len(positions_m)} positions")
        logged = {"world/agents"}
        self._rec.log("world/agents", rr.Points2D(positions_m, radii=AGENT_RADIUS_M, colors=agent_colors(ids),
                                                  labels=[str(i) for i in ids], draw_order=10.0))
        if trails is not None:
            logged |= self._log_trails(trails, trail_mask, ids)
        if predictions is not None or prototype_anchors is not None or adapted_anchors is not None:
            logged |= self._log_predictions(predictions, prediction_ids, prototype_anchors, adapted_anchors)
        if ego_xy_m is not None:
            logged |= self._log_ego(ego_xy_m, ego_goal_m, ego_heading)
        for path, points, radius, color in (("world/truth", truth_xy_m, AGENT_RADIUS_M, (160, 160, 160)),
                                            ("world/detections", detections_xy_m, AGENT_RADIUS_M / 3, (255, 255, 0))):
            if points is not None:
                self._rec.log(path, rr.Points2D(_as_points(points, path, (None, 2)), radii=radius, colors=color,
                                                draw_order=9.0))
                logged.add(path)
        for name, value in (metrics or {}).items():
            self._rec.log(f"metrics/{metric_unit(name)}/{name}", rr.Scalars(float(value)))
        for path in sorted(self._live - logged):
            self._rec.log(path, rr.Clear(recursive=False))
        self._live = logged
        if time.monotonic() - self._sink.flushed_at >= FLUSH_EVERY_S:
            self._sink.flush()  # a killed run keeps all but the last second

    def log_walls(self, segments_m: np.ndarray) -> None:
        """Log wall segments (K, 2, 2) [m], world frame, once for the whole recording (``world/walls``)."""
        segments_m = _as_points(segments_m, "segments_m", (None, 2, 2))
        self._rec.log("world/walls", rr.LineStrips2D(segments_m, radii=WALL_RADIUS_M, colors=WALL_RGB,
                                                     draw_order=6.0), static=True)

    def log_marker(self, step: int, name: str, xy_m: np.ndarray, label: str,
                   color: tuple[int, int, int]) -> None:
        """Mark an event at ``xy_m`` (2,) [m] from ``step`` on (``world/events/<name>``, kept in later steps)."""
        if self._sink.error is not None:
            raise self._sink.error
        self._rec.set_time("step", sequence=step)
        self._rec.set_time("time", duration=step * STEP_S)
        point = _as_points(np.reshape(xy_m, (1, 2)), "xy_m", (1, 2))
        self._rec.log(f"world/events/{name}", rr.Points2D(point, radii=MARKER_RADIUS_M, colors=color, labels=label,
                                                          draw_order=12.0))

    def _log_scene(self, scene: Scene) -> None:
        raster = scene_raster(scene)
        linear = np.eye(3)
        linear[:2, :2] = raster.world_from_raster[:2, :2]
        translation = [*raster.world_from_raster[:2, 2], 0.0]
        self._rec.log("world/scene", rr.Transform3D(translation=translation, mat3x3=linear), static=True)
        self._rec.log("world/scene/photo", rr.Image(raster.photo, draw_order=-20.0), static=True)
        self._rec.log("world/scene/walkable", rr.AnnotationContext([
            (WALKABLE, "walkable", (0, 0, 0, 0)), (BLOCKED, "blocked", (*BLOCKED_TINT_RGB, 90)),
            (OFF_PHOTO, "off photo", (0, 0, 0, 0))]), static=True)
        self._rec.log("world/scene/walkable", rr.SegmentationImage(raster.classes, draw_order=-10.0), static=True)

    def _log_trails(self, trails, trail_mask, ids: np.ndarray) -> set[str]:
        if isinstance(trails, np.ndarray):
            trails = _as_points(trails, "trails", (len(ids), None, 2), allow_nan=True)
            mask = np.isfinite(trails).all(-1) if trail_mask is None else np.asarray(trail_mask, bool)
            if mask.shape != trails.shape[:2]:
                raise ValueError(f"log_step: trail_mask must be {trails.shape[:2]}, got {mask.shape}")
            trails = [trail[keep] for trail, keep in zip(trails, mask, strict=True)]
        if len(trails) != len(ids):
            raise ValueError(f"log_step: {len(trails)} trails for {len(ids)} agents")
        trails = [_as_points(t, f"trails[{i}]", (None, 2)) for i, t in enumerate(trails)]
        drawn = [i for i, trail in enumerate(trails) if len(trail) >= 2]
        self._rec.log("world/trails", rr.LineStrips2D([trails[i] for i in drawn], radii=TRAIL_RADIUS_M,
                                                      colors=agent_colors(ids[drawn]), draw_order=5.0))
        return {"world/trails"}

    def _log_predictions(self, predictions, prediction_ids, prototype_anchors, adapted_anchors) -> set[str]:
        if prediction_ids is None:
            raise ValueError("log_step: prediction_ids is required with predictions or anchors")
        prediction_ids = np.asarray(prediction_ids, dtype=np.int64).reshape(-1)
        logged = set()
        if predictions is not None:
            predictions = _as_points(predictions, "predictions", (len(prediction_ids), None, None, 2))
            colors = np.c_[agent_colors(prediction_ids), np.full(len(prediction_ids), PREDICTION_ALPHA)]
            for agent_id, paths, color in zip(prediction_ids, predictions, colors, strict=True):
                path = f"world/predictions/{agent_id}"
                self._rec.log(path, rr.LineStrips2D(paths, radii=PATH_RADIUS_M, colors=color, draw_order=4.0))
                logged.add(path)
        for name, anchors, color in (("prototype", prototype_anchors, (*PROTOTYPE_RGB, 150)),
                                     ("adapted", adapted_anchors, (*ADAPTED_RGB, 200))):
            if anchors is not None:
                anchors = _as_points(anchors, f"{name}_anchors", (len(prediction_ids), None, None, 2))
                strips = anchors.reshape(-1, anchors.shape[2], 2)
                self._rec.log(f"world/anchors/{name}",
                              rr.LineStrips2D(strips, radii=PATH_RADIUS_M, colors=color, draw_order=3.0))
                logged.add(f"world/anchors/{name}")
        return logged

    def _log_ego(self, ego_xy_m, ego_goal_m, ego_heading=None) -> set[str]:
        ego = _as_points(np.reshape(ego_xy_m, (1, 2)), "ego_xy_m", (1, 2))
        self._rec.log("world/ego", rr.Points2D(ego, radii=EGO_RADIUS_M, colors=(255, 255, 255), labels="ego",
                                               draw_order=11.0))
        logged = {"world/ego"}
        if ego_heading is not None:
            heading = _as_points(np.reshape(ego_heading, (1, 2)), "ego_heading", (1, 2))
            self._rec.log("world/ego/heading", rr.Arrows2D(origins=ego, vectors=heading * EGO_RADIUS_M,
                                                           colors=(0, 0, 0), draw_order=12.0))
            logged.add("world/ego/heading")
        if ego_goal_m is None:
            return logged
        goal = _as_points(np.reshape(ego_goal_m, (1, 2)), "ego_goal_m", (1, 2))
        self._rec.log("world/ego/goal", rr.Points2D(goal, radii=EGO_RADIUS_M / 2, colors=GT_RGB, labels="goal",
                                                    draw_order=11.0))
        return logged | {"world/ego/goal"}


def _as_points(array, name: str, shape: tuple[int | None, ...], allow_nan: bool = False) -> np.ndarray:
    """float32 array of the given shape (None = any size), finite unless ``allow_nan``."""
    array = np.asarray(array, dtype=np.float32)
    wrong = array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape, strict=True))
    if wrong:
        letters = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"log_step: {name} must have shape {letters}, got {array.shape}")
    if not allow_nan and not np.isfinite(array).all():
        raise ValueError(f"log_step: {name} holds NaN or inf")
    return array


def _blueprint(scene: Scene | None, notes: bool = False) -> rrb.Blueprint:
    """Default layout: the world (y up, framed on the scene) beside one time-series view per metric unit (below the
    ``notes`` if there are some)."""
    bounds = None
    if scene is not None:
        height, width = scene.walkable.shape
        corners_m = scene.pixel_to_world(np.array([[0, 0], [width, 0], [0, height], [width, height]], float))
        low, high = corners_m.min(axis=0), corners_m.max(axis=0)
        bounds = rrb.VisualBounds2D(x_range=[low[0], high[0]], y_range=[-high[1], -low[1]])  # y flipped
    plots = [rrb.TimeSeriesView(origin=f"/metrics/{unit}", name=title) for unit, title in METRIC_VIEWS.items()]
    if notes:
        plots.insert(0, rrb.TextDocumentView(origin="/notes", name="notes"))
    return rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial2DView(origin="/", contents="/world/**", name="world", visual_bounds=bounds),
        rrb.Vertical(*plots),
        column_shares=[3, 2]))
