"""The crash-safe framed file under its former path: the code lives in :mod:`tactile_manip.logs.framed_file`
(the file formats sit below the sensors layer, so the data layer reads recordings without the sensors), and this
module names the same objects.
"""

from tactile_manip.logs.framed_file import (
    CRC32,
    TAG_EVENT,
    FramedWriter,
    Scan,
    json_default,
    read_header,
    scan_records,
)

__all__ = ["CRC32", "TAG_EVENT", "FramedWriter", "Scan", "json_default", "read_header", "scan_records"]
