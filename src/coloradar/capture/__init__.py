"""Raw captures of the user's own TI radars as ColoRadar runs (``coloradar import-capture``).

A bridge like :mod:`coloradar.interop`: it uses ``formats``, ``calib`` and ``dataset``'s layout;
only ``cli`` imports it. :mod:`.config` reads the radar configuration (SDK ``.cfg``, mmWave
Studio JSON, MMWCAS JSON), :mod:`.lvds` the DCA1000 and TDA2 byte layouts, :mod:`.packets` raw
DCA1000 packet dumps, :mod:`.tda2` MMWCAS capture folders, :mod:`.boards` the boards' antenna
layouts, and :mod:`.importer` writes the run (docs/capture.md).
"""

from .boards import BOARDS, Board, get_board, run_antenna
from .config import CaptureConfig, load_config, parse_cli_cfg, parse_mmwave_json
from .importer import MARKER, CaptureImport, ImportResult, import_capture
from .lvds import ByteLayout, decode_dca1000, decode_tda2
from .packets import PacketStream, read_packet_dump

__all__ = [
    "BOARDS",
    "MARKER",
    "Board",
    "ByteLayout",
    "CaptureConfig",
    "CaptureImport",
    "ImportResult",
    "PacketStream",
    "decode_dca1000",
    "decode_tda2",
    "get_board",
    "import_capture",
    "load_config",
    "parse_cli_cfg",
    "parse_mmwave_json",
    "read_packet_dump",
    "run_antenna",
]
