"""Live view of ``gatmo compare`` in a Rerun viewer, or recorded to an ``.rrd`` file.

:class:`RerunObserver` is handed to :func:`gatmo.pipeline.runs.compare` as ``observer``; the
comparison calls it per log and per scan and it logs what the two sides do:

======================================  =========================================================
entity                                  what
======================================  =========================================================
``world/map/static``                    the static map (textured quad at z = -0.02, static)
``world/map/gatmo``                     GATMO's reconfigured map, at each log start and change
``world/{static,gatmo}/pose``           the published pose, every scan (arrow)
``world/{static,gatmo}/trail``          the log's path so far, at the filter update rate
``world/{static,gatmo}/particles``      at most ``max_particles`` particles, at filter updates
``world/{static,gatmo}/scan``           the scan's endpoints from the published pose, same rate
``world/ground_truth/pose``             ground truth at the scans' stamps, when known
``world/ground_truth/trail``            the log's whole true route, from the log's start
``world/objects/{outlines,cells}``      GATMO's objects by status, when they change
``error/{static,gatmo}``                position error against ground truth [m], every scan
``events``                              GATMO's events (absent, relocated, added, ...)
======================================  =========================================================

Two timelines: ``scan`` (scan index, counted on across logs, so both sides of a log share it)
and ``time`` (log time, logs laid end to end). The world is z-up; the blueprint shows the two
sides from above next to each other, the error plot and the event log below.

``rerun`` (the ``rerun-sdk`` package, extra ``gatmo[rerun]``) is imported only here and only when
an observer is made; without it the constructor raises :class:`gatmo.errors.MissingExtraError`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gatmo.errors import ConfigError, GatmoError, MissingExtraError

MIN_RERUN = (0, 23)  # set_time(duration=...), rr.Scalars, connect_grpc

SIDE_COLORS = {"static": (230, 110, 40), "gatmo": (40, 120, 235), "ground_truth": (40, 170, 60)}
STATUS_COLORS = {  # placed as seen (U), placed after a move (M), absent (A), seen only (Gamma)
    "U": (150, 150, 160),
    "M": (40, 120, 235),
    "A": (220, 40, 40),
    "Gamma": (240, 170, 0),
}
_Z = {"map/static": -0.02, "map/gatmo": -0.01, "objects": 0.01, "scan": 0.02, "particles": 0.03,
      "trail": 0.04, "pose": 0.05}


def import_rerun():
    """``rerun``, or :class:`MissingExtraError` naming the ``rerun`` extra."""
    try:
        import rerun as rr
    except ImportError as exc:
        raise MissingExtraError("rerun", "rerun") from exc
    version = tuple(int(p) for p in rr.__version__.split(".")[:2] if p.isdigit())
    if version < MIN_RERUN:
        need = ".".join(map(str, MIN_RERUN))
        raise ConfigError(
            f"rerun-sdk {rr.__version__} is too old (gatmo needs {need} or newer): "
            f"pip install -U 'gatmo[rerun]'",
            field="rerun",
        )
    return rr


class RerunObserver:
    """Logs a comparison to Rerun. Use as a context manager (``close`` flushes the file).

    Args:
        spawn: start a local viewer (or reuse the one already listening) and stream to it.
        url: stream to a viewer at this gRPC URL instead (``rerun+http://HOST:9876/proxy``).
        save: write an ``.rrd`` file (also together with ``spawn`` / ``url``).
        max_particles: particles logged per filter update (evenly subsampled).
        max_trail: vertices of a logged trail (the path so far, evenly subsampled).
    """

    def __init__(
        self,
        *,
        spawn: bool = False,
        url: str | None = None,
        save: str | Path | None = None,
        application_id: str = "gatmo_compare",
        max_particles: int = 500,
        max_trail: int = 1000,
    ) -> None:
        if not (spawn or url or save):
            raise ConfigError("nothing to log to: give spawn, url or save", field="rerun")
        self.rr = rr = import_rerun()
        self.max_particles = int(max_particles)
        self.max_trail = int(max_trail)
        self.rec = rr.RecordingStream(application_id)
        sinks = []
        if save is not None:
            path = Path(save)
            if not path.parent.is_dir():
                raise ConfigError(f"no such folder: {path.parent}", field="--rerun-save")
            sinks.append(rr.FileSink(str(path)))
        streaming = spawn or url is not None
        if spawn and url is None:
            try:
                rr.spawn(connect=False, recording=self.rec, executable_path=_viewer_executable())
            except Exception as exc:  # no viewer executable, ...
                raise GatmoError(f"could not start a Rerun viewer: {exc}", field="rerun") from exc
        if streaming:
            sinks.append(rr.GrpcSink(url) if url is not None else rr.GrpcSink())
        if hasattr(self.rec, "set_sinks"):
            self.rec.set_sinks(*sinks)
        elif len(sinks) == 1 and save is not None:
            self.rec.save(str(save))
        elif len(sinks) == 1:
            self.rec.connect_grpc(url)
        else:
            raise ConfigError(f"rerun-sdk {rr.__version__} streams and saves one at a time",
                              field="rerun")
        self._closed = False
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        if streaming:  # fail now, not after the whole comparison
            self._flush_sinks(15.0, "the viewer did not answer (no display? --rerun-save FILE.rrd "
                              "records without one)")
        self._blueprint_sent = False
        self._styled: set[str] = set()  # entities whose static colour and size are sent
        # per log
        self._offset = 0  # scan index of the log's first scan on the "scan" timeline
        self._t_offset = 0.0
        self._stamps = np.zeros(0)
        self._gt = None  # (N, 3) ground truth at the scans' stamps (NaN outside)
        self._trail: dict[str, np.ndarray] = {}  # side -> (N, 3) poses of this log, by scan
        self._sent: dict[str, int] = {}  # side -> first scan whose pose is not sent yet
        self._updates: dict[str, int | None] = {}

    # ----------------------------------------------------------------- lifetime
    def __enter__(self) -> RerunObserver:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.close()
        except GatmoError:
            if exc_type is None:  # else the run's own error is the one to report
                raise

    def close(self) -> None:
        """Flush and detach the sinks (the ``.rrd`` file is complete after this)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._flush_sinks(30.0, "the viewer went away; what was logged since is lost")
        finally:
            self.rec.disconnect()

    def _flush_sinks(self, timeout_s: float, hint: str) -> None:
        try:
            self.rec.flush(timeout_sec=timeout_s)
        except TypeError:  # an SDK without the timeout
            self.rec.flush()
        except Exception as exc:
            self._closed = True
            self.rec.disconnect()
            raise GatmoError(f"{hint}: {exc}", field="rerun") from exc

    # ------------------------------------------------------------------- timing
    def _set_time(self, i: int) -> None:
        """Put the logging cursor on scan ``i`` of the current log."""
        i = int(min(max(i, 0), max(len(self._stamps) - 1, 0)))
        t = self._t_offset
        if len(self._stamps):
            t += float(self._stamps[i] - self._stamps[0])
        self.rec.set_time("scan", sequence=self._offset + i)
        self.rec.set_time("time", duration=t)

    # --------------------------------------------------------------------- maps
    def on_map(self, name: str, grid) -> None:
        """An occupancy grid as a textured quad at ``world/map/{name}``.

        ``static`` is logged once as static data (and sets up the blueprint); other names are
        logged at the current scan, so the viewer shows the map as it was then.
        """
        rr = self.rr
        xmin, xmax, ymin, ymax = grid.extent_xy
        z = _Z.get(f"map/{name}", 0.0)
        corners = np.array([[xmin, ymin, z], [xmax, ymin, z], [xmax, ymax, z], [xmin, ymax, z]])
        # cells[iy, ix]: row 0 is the lowest y, and texture row 0 is v = 0
        mesh = rr.Mesh3D(
            vertex_positions=corners,
            triangle_indices=[[0, 1, 2], [0, 2, 3]],
            vertex_texcoords=[[0, 0], [1, 0], [1, 1], [0, 1]],
            albedo_texture=grid_image(grid),
        )
        static = name == "static"
        self.rec.log(f"world/map/{name}", mesh, static=static)
        if static and not self._blueprint_sent:
            self._send_blueprint(grid)

    def _send_blueprint(self, grid) -> None:
        """Two top-down views (static | gatmo), the error plot and the event log."""
        try:
            import rerun.blueprint as rrb

            xmin, xmax, ymin, ymax = grid.extent_xy
            cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
            size = max(xmax - xmin, ymax - ymin)
            # from above, tilted 20 degrees to the south (straight down, z-up is degenerate)
            eye = rrb.EyeControls3D(position=(cx, cy - 0.36 * size, size),
                                    look_target=(cx, cy, 0.0), eye_up=(0.0, 0.0, 1.0))
            common = ["world/ground_truth/**", "world/objects/**"]

            def view(side: str, title: str):
                return rrb.Spatial3DView(
                    name=title, origin="world",
                    contents=[f"world/map/{side}", f"world/{side}/**", *common],
                    eye_controls=eye, line_grid=False,
                )

            bp = rrb.Blueprint(
                rrb.Vertical(
                    rrb.Horizontal(view("static", "static localizer"),
                                   view("gatmo", "full stack (gatmo)")),
                    rrb.Horizontal(rrb.TimeSeriesView(name="position error [m]", origin="error"),
                                   rrb.TextLogView(name="events", origin="events")),
                    row_shares=[3, 1],
                ),
                collapse_panels=True,
            )
            self.rec.send_blueprint(bp)
        except Exception:  # a blueprint is cosmetic: the data is complete without it
            pass
        self._blueprint_sent = True

    # --------------------------------------------------------------------- logs
    def on_log(self, index: int, name: str, stamps_s: np.ndarray, gt=None) -> None:
        """A new log: its scans' stamps and ground truth (a ``GroundTruth`` or None)."""
        rr = self.rr
        if len(self._stamps):
            self._offset += len(self._stamps)
            self._t_offset += float(self._stamps[-1] - self._stamps[0]) + 1.0
        self._stamps = np.asarray(stamps_s, dtype=float)
        n = len(self._stamps)
        self._trail = {}
        self._sent = {}
        self._updates = {}
        self._gt = None
        self._set_time(0)
        self.rec.log("events", rr.TextLog(f"log {index + 1}: {name} ({n} scans)", level="INFO"))
        if gt is None or n == 0:
            return
        from gatmo.geometry import interpolate_poses

        g = interpolate_poses(gt.stamps_s, gt.poses_xytheta, self._stamps)
        outside = ((self._stamps < gt.stamps_s[0] - 0.05)
                   | (self._stamps > gt.stamps_s[-1] + 0.05))
        g[outside] = np.nan
        self._gt = g
        have = np.flatnonzero(~np.isnan(g[:, 0]))
        if len(have):
            self._send_poses("ground_truth", have, g[have])
            self._log_trail("ground_truth", g[have])  # the whole route, from the log's start

    # -------------------------------------------------------------------- scans
    def on_step(self, side: str, i: int, scan, step, stack) -> None:
        """One scan of one side, as :func:`gatmo.pipeline.runs.run_side` has it.

        The pose is logged every scan; scan points, particles and the trail only when the
        localizer ran a filter update on this scan (its ``stats.sensor_updates`` moved).
        """
        from gatmo.geometry import compose, transform_points

        loc = stack.localizer
        n_upd = getattr(getattr(loc, "stats", None), "sensor_updates", None)
        updated = i == 0 or n_upd is None or n_upd != self._updates.get(side)
        self._updates[side] = n_upd
        points = particles = None
        if updated:
            points = transform_points(compose(step.pose_xytheta, scan.laser_pose_xytheta),
                                      scan.points_laser_xy())
            particles = getattr(loc, "particles", None)
        self.on_scan(side, i, step.pose_xytheta, points, particles)
        if step.events:
            self.on_events(step.events)
        mapper = getattr(stack, "mapper", None)
        if mapper is not None and (step.events or step.map_changed):
            self.on_objects(mapper.object_map.objects)
            if step.map_changed:
                self.on_map("gatmo", mapper.grid())

    def on_scan(self, side: str, i: int, pose_xytheta, scan_points_xy_map=None,
                particles_xytheta=None) -> None:
        """Scan ``i`` of the current log on one side.

        The pose (and its error against ground truth) is kept for every scan; it is sent, with
        the trail, the scan's points and the particles, when those are given (the caller passes
        them at the filter update rate) and at the log's last scan, so a frame costs a few
        logging calls however many scans lie between two filter updates.
        """
        rr = self.rr
        buf = self._trail.get(side)
        if buf is None or len(buf) <= i:
            grown = np.full((max(len(self._stamps), 2 * (i + 1)), 3), np.nan)
            if buf is not None:
                grown[: len(buf)] = buf
            self._trail[side] = buf = grown
        buf[i] = np.asarray(pose_xytheta, dtype=float)
        last = i >= len(self._stamps) - 1
        if scan_points_xy_map is None and particles_xytheta is None and not last:
            return
        self._flush(side, i)
        self._set_time(i)
        color = SIDE_COLORS.get(side, (200, 200, 200))
        trail = buf[: i + 1]
        self._log_trail(side, trail[~np.isnan(trail[:, 0])])
        if scan_points_xy_map is not None:
            self.rec.log(f"world/{side}/scan", rr.Points3D(
                _xyz(scan_points_xy_map, _Z["scan"]), radii=0.03, colors=color))
        if particles_xytheta is not None and len(particles_xytheta):
            p = subsample(np.asarray(particles_xytheta), self.max_particles)
            self.rec.log(f"world/{side}/particles", rr.Points3D(
                _xyz(p[:, :2], _Z["particles"]), radii=0.02, colors=_lighter(color)))

    def _flush(self, side: str, upto: int) -> None:
        """Send the poses (and errors) of scans not sent yet up to ``upto``, one call each."""
        start = self._sent.get(side, 0)
        buf = self._trail.get(side)
        if buf is None or upto < start:
            return
        idx = np.arange(start, min(upto + 1, len(buf)))
        idx = idx[~np.isnan(buf[idx, 0])]
        self._sent[side] = upto + 1
        if len(idx) == 0:
            return
        self._send_poses(side, idx, buf[idx])
        if self._gt is not None:
            ok = idx[idx < len(self._gt)]
            ok = ok[~np.isnan(self._gt[ok, 0])]
            if len(ok):
                err = np.hypot(*(buf[ok, :2] - self._gt[ok, :2]).T)
                self.rec.send_columns(f"error/{side}", indexes=self._time_columns(ok),
                                      columns=self.rr.Scalars.columns(scalars=err))

    def _time_columns(self, idx: np.ndarray) -> list:
        rr = self.rr
        t = self._t_offset + (self._stamps[idx] - self._stamps[0]) if len(self._stamps) \
            else np.zeros(len(idx))
        return [rr.TimeColumn("scan", sequence=self._offset + idx),
                rr.TimeColumn("time", duration=np.asarray(t, dtype=float))]

    def _send_poses(self, side: str, idx: np.ndarray, poses: np.ndarray) -> None:
        """One arrow per scan at ``world/{side}/pose``, as columns (one row per scan); colour
        and size are static, sent once."""
        rr = self.rr
        entity = f"world/{side}/pose"
        if entity not in self._styled:
            self._styled.add(entity)
            self.rec.log(entity, rr.Arrows3D.from_fields(
                colors=[SIDE_COLORS.get(side, (200, 200, 200))], radii=[0.03]), static=True)
        vec = 0.5 * np.column_stack([np.cos(poses[:, 2]), np.sin(poses[:, 2]),
                                     np.zeros(len(idx))])
        self.rec.send_columns(
            entity, indexes=self._time_columns(idx),
            columns=rr.Arrows3D.columns(origins=_xyz(poses[:, :2], _Z["pose"]), vectors=vec),
        )

    def _log_trail(self, side: str, poses: np.ndarray) -> None:
        if len(poses) < 2:
            return
        idx = np.unique(np.linspace(0, len(poses) - 1, min(len(poses), self.max_trail))
                        .astype(int))
        self.rec.log(f"world/{side}/trail", self.rr.LineStrips3D(
            [_xyz(poses[idx, :2], _Z["trail"])], radii=0.02,
            colors=SIDE_COLORS.get(side, (200, 200, 200))))

    # ------------------------------------------------------------------ objects
    def on_objects(self, objects) -> None:
        """GATMO's object map at the current scan: outlines with labels, and cells, by status.

        Walls and other structure are left out (the map shows them)."""
        rr = self.rr
        strips, labels, colors = [], [], []
        cells, cell_colors = [], []
        for o in objects:
            if o.structure or len(o.shape_xy) == 0:
                continue
            color = STATUS_COLORS.get(o.status, (200, 200, 200))
            strips.append(_xyz(outline(o), _Z["objects"]))
            labels.append(f"{o.id} {o.label or ''} {o.status}".replace("  ", " "))
            colors.append(color)
            cells.append(o.cells_world())
            cell_colors.append(np.tile(color, (len(o.shape_xy), 1)))
        if not strips:
            self.rec.log("world/objects", rr.Clear(recursive=True))
            return
        self.rec.log("world/objects/outlines", rr.LineStrips3D(
            strips, labels=labels, colors=colors, radii=0.02))
        self.rec.log("world/objects/cells", rr.Points3D(
            _xyz(np.concatenate(cells), _Z["objects"]),
            colors=np.concatenate(cell_colors).astype(np.uint8), radii=0.025))

    def on_events(self, events) -> None:
        """GATMO's events at the current scan, one text line each."""
        for ev in events:
            d = ev.as_dict() if hasattr(ev, "as_dict") else dict(ev)
            text = f"{d.get('kind')} object {d.get('object_id')}"
            if d.get("label"):
                text += f" ({d['label']})"
            if d.get("pose_new") is not None:
                x, y = (float(v) for v in list(d["pose_new"])[:2])
                text += f" at ({x:.2f}, {y:.2f})"
            self.rec.log("events", self.rr.TextLog(text, level="INFO"))

    def on_run_end(self, side: str, stack, events=()) -> None:
        """A side finished a log; with GATMO: the end-of-log events, objects and map."""
        n = len(self._stamps)
        if n == 0:
            return
        self._flush(side, n - 1)
        self._set_time(n - 1)
        if events:
            self.on_events(events)
        mapper = getattr(stack, "mapper", None)
        if mapper is not None:
            self.on_objects(mapper.object_map.objects)
            self.on_map("gatmo", mapper.grid())


# ------------------------------------------------------------------------------ helpers
def _viewer_executable() -> str | None:
    """The ``rerun`` viewer installed beside this Python (a venv not on PATH), else None (PATH)."""
    import shutil
    import sys

    if shutil.which("rerun"):
        return None
    exe = Path(sys.executable).parent / ("rerun.exe" if sys.platform == "win32" else "rerun")
    return str(exe) if exe.exists() else None


def grid_image(grid) -> np.ndarray:
    """(H, W, 3) uint8 in map_server grey levels: free white, occupied black, unknown grey."""
    from gatmo.maps.grid import FREE, OCCUPIED

    img = np.full(grid.cells.shape, 205, dtype=np.uint8)
    img[grid.cells == FREE] = 254
    img[grid.cells == OCCUPIED] = 0
    return np.repeat(img[:, :, None], 3, axis=2)


def subsample(rows: np.ndarray, k: int) -> np.ndarray:
    """At most ``k`` rows, evenly spread (no random numbers: the runs' generators are left
    alone)."""
    if len(rows) <= k:
        return rows
    return rows[np.linspace(0, len(rows) - 1, k).astype(int)]


def outline(obj) -> np.ndarray:
    """Closed (5, 2) outline of an object: its shape's box in its own frame, at its pose."""
    from gatmo.geometry import transform_points

    h = obj.resolution_m / 2
    (x0, y0), (x1, y1) = obj.shape_xy.min(axis=0) - h, obj.shape_xy.max(axis=0) + h
    box = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    return transform_points(obj.pose_xytheta, box)


def _xyz(xy: np.ndarray, z: float) -> np.ndarray:
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    return np.column_stack([xy, np.full(len(xy), z)])


def _lighter(color) -> tuple:
    return tuple(int(c + (255 - c) * 0.45) for c in color)
