"""The swarm in 3-D in a browser, live or replayed: rerun's web viewer, served from this
machine.

The view serves two things: rerun's viewer itself (HTML and WebAssembly, shipped inside the
rerun SDK's wheel, so no internet and no account are needed) and the swarm's data over
gRPC, which the page streams from. Any browser that reaches this machine can open the page;
the view only shows, it cannot act on the swarm. docs/view.md says why rerun.
"""

from __future__ import annotations

import contextlib
import math
import socket
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from fishswarm.bluebot.parameters import BODY_LENGTH, Tank
from fishswarm.study.experiment import METRIC_LABELS
from fishswarm.study.scene import (
    LANDMARK_RGB,
    ROLE_RGB,
    TARGET_RGB,
    WALL_RGB,
    Scene,
    Stage,
    tank_edges,
    upright,
)
from fishswarm.study.view_settings import ViewError, ViewSettings

if TYPE_CHECKING:
    import rerun

TIMELINE = "time"
"""The timeline of the view: simulated time, s."""
APPLICATION = "fishswarm"
"""The application the view's recordings belong to (the page groups them under it)."""


def _rerun() -> Any:
    try:
        import rerun
    except ImportError:
        raise ViewError(
            "the view (of a live swarm or of a recording) needs the rerun SDK: pip install -e "
            "'.[view]' (or pip install rerun-sdk)"
        ) from None
    return rerun


def _blueprint(rr: Any) -> Any:
    """The page's layout: the tank on the left, the metrics over time on the right."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="tank", origin="/tank"),
            rrb.Vertical(
                *(
                    rrb.TimeSeriesView(name=title, origin=f"/metrics/{group}")
                    for group, title in METRIC_GROUPS.items()
                )
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


METRIC_GROUPS = {
    "distances": "distances (m)",
    "school": "counts and fractions",
    "effort": "effort (gain-weighted fin beats)",
}
"""The plots beside the tank: metrics that share a scale share a plot."""


def metric_path(name: str) -> str:
    """Where a metric is drawn: with the other lengths, the fish's summed effort apart (it
    only grows), the other numbers together."""
    if METRIC_LABELS.get(name, "").endswith("(m)"):
        group = "distances"
    elif name == "effort":
        group = "effort"
    else:
        group = "school"
    return f"metrics/{group}/{name}"


class LiveView:
    """A swarm shown in the browser; use :func:`open_live_view`.

    Attributes:
        settings: where it is served.
        scenes: scenes shown so far.
    """

    def __init__(self, recording: rerun.RecordingStream, settings: ViewSettings) -> None:
        self._served = recording
        """The recording whose gRPC server the page streams from (it lives as long as the
        view)."""
        self._recording = recording
        """The recording drawn into now: the served one, or a later run's."""
        self._rr = _rerun()
        self.settings = settings
        self.scenes = 0
        self._metrics: set[str] = set()
        self._stage = Stage(Tank().size)
        """The tank and landmark: what is drawn is drawn upright in the tank (:func:`upright`)."""

    def start_run(self, name: str) -> None:
        """Draw what follows into a recording of its own, called ``name``, on the same page:
        the page lists every run apart (the earlier ones stay, to scrub through) and turns
        to the newest. The stage is drawn again until :meth:`show_stage` says otherwise."""
        rr = self._rr
        recording = rr.RecordingStream(application_id=APPLICATION, recording_id=name)
        try:
            recording.connect_grpc(self.settings.local_stream_url, default_blueprint=_blueprint(rr))
        except Exception as error:  # rerun's errors are plain RuntimeErrors
            raise ViewError(f"cannot add the run to the view: {error}") from None
        recording.send_recording_name(name)
        self._recording.flush()
        self._recording = recording
        self.scenes = 0
        self._metrics = set()
        self.show_stage(self._stage)

    def flush(self) -> None:
        """Send all that is drawn to the page's stream."""
        self._recording.flush()
        if self._served is not self._recording:
            self._served.flush()

    def show_stage(self, stage: Stage) -> None:
        """Draw the tank's walls and the landmark (they stay for the whole run)."""
        rr, log = self._rr, self._recording.log
        self._stage = stage
        log("tank", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        log(
            "tank/walls",
            rr.LineStrips3D(list(tank_edges(stage.tank)), colors=WALL_RGB, radii=0.003),
            static=True,
        )
        if stage.landmark is not None:
            log(
                "tank/landmark",
                rr.Points3D([upright(stage.landmark, stage.tank)], colors=LANDMARK_RGB, radii=0.02),
                static=True,
            )

    def show(self, scene: Scene, metrics: dict[str, float]) -> None:
        """Draw the swarm at one moment (fish as arrows along their bodies, coloured by
        role; a formation's fitted target, or its completed local shapes' sides) and its
        metrics, at the scene's time."""
        rr, log = self._rr, self._recording.log
        self._recording.set_time(TIMELINE, duration=scene.time)
        colours = scene.colours()
        scene = scene.upright(self._stage.tank)
        log(
            "tank/fish",
            rr.Points3D(scene.position, colors=colours, radii=0.25 * BODY_LENGTH),
        )
        log(
            "tank/heading",
            rr.Arrows3D(
                origins=scene.position, vectors=scene.heading * BODY_LENGTH, colors=colours,
                radii=0.06 * BODY_LENGTH,
            ),
        )  # fmt: skip
        if scene.slots is not None:
            log(
                "tank/target",
                rr.Points3D(scene.slots, colors=TARGET_RGB, radii=0.1 * BODY_LENGTH),
            )
        if scene.edges is not None:
            log(
                "tank/shapes",
                rr.LineStrips3D(list(scene.edges), colors=ROLE_RGB["joined"], radii=0.002),
            )
        for name, value in metrics.items():
            if value is None or not math.isfinite(value):
                continue
            path = metric_path(name)
            if path not in self._metrics:
                self._metrics.add(path)
                log(path, rr.SeriesLines(names=METRIC_LABELS.get(name, name)), static=True)
            log(path, rr.Scalars(float(value)))
        self.scenes += 1


def _check_free(port: int, what: str) -> None:
    """Fail clearly if ``port`` is taken (rerun only logs it, and serves nothing)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        # As servers do: a port whose last connections are still closing counts as free.
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("0.0.0.0", port))
        except OSError as error:
            flag = "--web-port" if what == "page" else "--grpc-port"
            raise ViewError(
                f"port {port} for the view's {what} is taken ({error.strerror}): another view "
                f"may be running; choose another with {flag}"
            ) from None


@contextlib.contextmanager
def open_live_view(settings: ViewSettings, *, name: str = "fishswarm") -> Iterator[LiveView]:
    """Serve a live view (the page and the data stream) for the block's duration.

    Raises:
        ViewError: the rerun SDK is missing, or a port is taken.
    """
    rr = _rerun()
    for port, what in ((settings.web_port, "page"), (settings.grpc_port, "data stream")):
        _check_free(port, what)
    recording = rr.RecordingStream(application_id=APPLICATION, recording_id=name)
    try:
        recording.serve_grpc(
            grpc_port=settings.grpc_port,
            default_blueprint=_blueprint(rr),
            server_memory_limit=settings.memory_limit,
        )
        rr.serve_web_viewer(
            web_port=settings.web_port,
            open_browser=settings.open_browser,
            connect_to=settings.stream_url,
        )
    except Exception as error:  # rerun's errors are plain RuntimeErrors
        raise ViewError(f"cannot serve the view: {error}") from None
    recording.send_recording_name(name)
    view = LiveView(recording, settings)
    try:
        yield view
    finally:
        view.flush()
