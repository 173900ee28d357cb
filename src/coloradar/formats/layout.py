"""Where every stream of a run lives: one table per dataset layout (ColoRadar, ColoRadar+).

Every reader and writer of run folders — the dataset reader, ``coloradar process``, the
simulator, the viewers and the map builder — takes folder names, file prefixes and frame
numbering from here, so that what one writes the others read.

A frame stream is a folder holding a timestamps file and a data folder of files
``<prefix>_<n>.bin``; the ``k``-th timestamp belongs to file number ``first_frame + k``
(0 in the original ColoRadar release, 1 in ColoRadar+ and in a later derived release of
ColoRadar: readers accept both). Tables (IMU, poses) are a timestamps file beside a text file
of one row per timestamp. See ``docs/layout.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from ..errors import MissingDataError

__all__ = [
    "COLORADAR",
    "COLORADAR_PLUS",
    "LAYOUTS",
    "PROCESS_PRODUCTS",
    "FrameKind",
    "FrameLayout",
    "RunLayout",
    "TableLayout",
    "get_layout",
]

FrameKind = Literal["adc", "heatmap", "radar_points", "lidar_points", "rgb_image", "depth_image"]
"""How the files of a frame stream are decoded."""

TableKind = Literal["imu", "poses"]


@dataclass(frozen=True)
class FrameLayout:
    """One stream of frames stored one file each.

    Attributes
    ----------
    name
        ``"<sensor>/<product>"``, e.g. ``"cascade/adc"``.
    folder
        Folder (relative to the run) holding the timestamps file.
    data
        Folder holding the frame files.
    prefix
        Frame files are ``<data>/<prefix>_<n>.bin``.
    kind
        How a file is decoded (:data:`FrameKind`).
    timestamps
        Name of the timestamps file inside ``folder``.
    alt_data
        Other data folders some copies of the dataset use (read only; writers use ``data``).
    """

    name: str
    folder: str
    data: str
    prefix: str
    kind: FrameKind
    timestamps: str = "timestamps.txt"
    alt_data: tuple[str, ...] = ()

    @property
    def sensor(self) -> str:
        """The part of :attr:`name` before the slash (``cascade``, ``lidar``, ``camera``…)."""
        return self.name.split("/", 1)[0]

    @property
    def product(self) -> str:
        """The part of :attr:`name` after the slash (``adc``, ``heatmaps``, ``pointclouds``…)."""
        return self.name.split("/", 1)[1]

    @property
    def timestamps_path(self) -> str:
        """Run-relative path of the timestamps file."""
        return f"{self.folder}/{self.timestamps}"

    def frame_name(self, number: int) -> str:
        """File name of frame number ``number`` (as on disk, 0- or 1-based)."""
        return f"{self.prefix}_{int(number)}.bin"

    def frame_path(self, number: int) -> str:
        """Run-relative path of frame number ``number``."""
        return f"{self.data}/{self.frame_name(number)}"


@dataclass(frozen=True)
class TableLayout:
    """A stream stored as one text table: ``<folder>/<timestamps>`` and ``<folder>/<file>``.

    Attributes
    ----------
    name
        ``"imu"``, ``"groundtruth"`` or ``"vicon"``.
    folder, file, timestamps
        Run-relative folder, the table's file name, the timestamps file name.
    kind
        ``"imu"`` (ax ay az gx gy gz rows) or ``"poses"`` (x y z qx qy qz qw rows).
    """

    name: str
    folder: str
    file: str
    kind: TableKind
    timestamps: str = "timestamps.txt"

    @property
    def path(self) -> str:
        """Run-relative path of the table."""
        return f"{self.folder}/{self.file}"

    @property
    def timestamps_path(self) -> str:
        """Run-relative path of the timestamps file."""
        return f"{self.folder}/{self.timestamps}"


def _frames(*streams: FrameLayout) -> dict[str, FrameLayout]:
    return {s.name: s for s in streams}


def _tables(*tables: TableLayout) -> dict[str, TableLayout]:
    return {t.name: t for t in tables}


@dataclass(frozen=True)
class RunLayout:
    """The layout of one dataset release: its streams, numbering, run folders, extrinsics.

    Attributes
    ----------
    name
        ``"coloradar"`` or ``"coloradar_plus"``.
    title
        Human-readable name.
    frames
        Frame streams by name (``"cascade/adc"`` …).
    tables
        Table streams by name (``"imu"``, ``"groundtruth"``, ``"vicon"``).
    first_frame
        Number of the first frame file that writers use (readers accept 0 and 1).
    runs_folder
        Folder of the dataset root that holds the runs (``""``: the root itself).
    transforms
        Sensor name -> file in ``calib/transforms`` holding its ``base_T_sensor``.
    radars
        Radars a run of this layout may hold.
    calib_radars
        Radars whose calibration folders ``calib/`` holds.
    extra_folders
        Run sub-folders that are not streams but are part of the layout (``camera``).
    """

    name: str
    title: str
    frames: Mapping[str, FrameLayout]
    tables: Mapping[str, TableLayout]
    first_frame: int
    runs_folder: str
    transforms: Mapping[str, str]
    radars: tuple[str, ...]
    calib_radars: tuple[str, ...]
    extra_folders: tuple[str, ...] = field(default=())

    def frame(self, name: str) -> FrameLayout:
        """The frame stream ``name``; MissingDataError naming the layout when it has none."""
        try:
            return self.frames[name]
        except KeyError:
            raise MissingDataError(f"the {self.title} layout has no {name} stream (it has "
                           f"{', '.join(self.frames)})") from None

    @property
    def stream_names(self) -> tuple[str, ...]:
        """Every stream name: frame streams, then tables."""
        return (*self.frames, *self.tables)

    @property
    def sensor_folders(self) -> tuple[str, ...]:
        """Top-level folders of a run (``cascade``, ``lidar``, ``imu`` …)."""
        tops = [s.folder.split("/", 1)[0] for s in self.frames.values()]
        tops += [t.folder.split("/", 1)[0] for t in self.tables.values()]
        return tuple(dict.fromkeys([*tops, *self.extra_folders]))

    @property
    def run_markers(self) -> tuple[str, ...]:
        """Folders of which a run has at least one (a calib folder has ``cascade/`` too, but
        none of these)."""
        marks = [s.folder for s in self.frames.values()]
        marks += [t.folder for t in self.tables.values()]
        return tuple(dict.fromkeys(marks))

    def radar_streams(self, radar: str) -> dict[str, FrameLayout]:
        """Product -> stream of one radar (``adc``, ``heatmaps``, ``pointclouds``)."""
        return {s.product: s for s in self.frames.values() if s.sensor == radar}


def _radar(radar: str) -> tuple[FrameLayout, FrameLayout, FrameLayout]:
    return (
        FrameLayout(f"{radar}/adc", f"{radar}/adc_samples", f"{radar}/adc_samples/data",
                    "frame", "adc"),
        FrameLayout(f"{radar}/heatmaps", f"{radar}/heatmaps", f"{radar}/heatmaps/data",
                    "heatmap", "heatmap"),
        FrameLayout(f"{radar}/pointclouds", f"{radar}/pointclouds",
                    f"{radar}/pointclouds/data", "radar_pointcloud", "radar_points"),
    )


# The lidar's frame files lie directly in lidar/pointclouds (no data/ folder), with the
# timestamps one level up; some copies add a data/ folder, which readers accept.
_LIDAR = FrameLayout("lidar/pointclouds", "lidar", "lidar/pointclouds", "lidar_pointcloud",
                     "lidar_points", alt_data=("lidar/pointclouds/data",))
_IMU = TableLayout("imu", "imu", "imu_data.txt", "imu")
_GROUNDTRUTH = TableLayout("groundtruth", "groundtruth", "groundtruth_poses.txt", "poses")

COLORADAR = RunLayout(
    name="coloradar",
    title="ColoRadar",
    frames=_frames(*_radar("cascade"), *_radar("single_chip"), _LIDAR),
    tables=_tables(_IMU, _GROUNDTRUTH,
                   TableLayout("vicon", "vicon", "vicon_poses.txt", "poses")),
    first_frame=0,
    runs_folder="",
    transforms={s: f"base_to_{s}.txt" for s in ("cascade", "single_chip", "lidar", "imu",
                                                "vicon")},
    radars=("cascade", "single_chip"),
    calib_radars=("cascade", "single_chip"),
)
"""The original ColoRadar release (Kramer et al., IJRR 2022), and ``coloradar process``
output. ``cascade/pointclouds`` is not shipped, but ``process`` writes it."""

COLORADAR_PLUS = RunLayout(
    name="coloradar_plus",
    title="ColoRadar+",
    frames=_frames(
        *_radar("cascade"), _LIDAR,
        # Raw camera images, one file each; sizes come from <folder>/<kind>_cam_info.json.
        FrameLayout("camera/rgb", "camera", "camera/images/rgb", "camera_rgb_image",
                    "rgb_image", timestamps="rgb_timestamps.txt"),
        FrameLayout("camera/depth", "camera", "camera/images/depth", "camera_depth_image",
                    "depth_image", timestamps="depth_timestamps.txt"),
    ),
    tables=_tables(_IMU, _GROUNDTRUTH),
    first_frame=1,
    runs_folder="kitti",
    transforms={"cascade": "base_to_radar.txt", "lidar": "base_to_lidar.txt",
                "imu": "base_to_imu.txt"},
    radars=("cascade",),
    calib_radars=("cascade",),
)
"""ColoRadar+ as read by arpg/coloradar-library and written by
arpg/coloradar_plus_processing_tools: runs in ``<root>/kitti/``, frames numbered from 1,
cascade radar only, a camera (rgb + depth), extrinsics ``base_to_radar.txt`` (the cascade),
``base_to_lidar.txt``, ``base_to_imu.txt``."""

LAYOUTS: dict[str, RunLayout] = {COLORADAR.name: COLORADAR, COLORADAR_PLUS.name: COLORADAR_PLUS}
"""Every known layout by name."""

PROCESS_PRODUCTS = ("heatmaps", "pointclouds")
"""Products ``coloradar process`` writes for each radar, in the :data:`COLORADAR` layout."""


def get_layout(layout: str | RunLayout) -> RunLayout:
    """A layout by name (or the layout itself); MissingDataError listing the known ones."""
    if isinstance(layout, RunLayout):
        return layout
    try:
        return LAYOUTS[layout]
    except KeyError:
        raise MissingDataError(f"unknown dataset layout {layout!r}; expected one of "
                       f"{', '.join(LAYOUTS)}") from None
