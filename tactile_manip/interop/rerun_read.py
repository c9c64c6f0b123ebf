"""Reading a ``.rrd`` file back into numpy: one entity's timelines and components, in logging order.

For checking an export or plotting what was logged without the viewer. rerun-sdk 0.41 reads chunks with
``rerun.chunk.RrdReader``; releases before it that have ``rerun.dataframe`` (0.24) are queried through that
instead (columns renamed to the same ``Archetype:field`` names) on ``log_tick``, one row per logging call,
or for data sent column-wise, which has no ``log_tick``, on ``frame``, one row per frame number.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.interop.rerun_log import require_rerun

ROW_ID = "rerun.controls.RowId"
NO_TIME = np.iinfo(np.int64).min  # a row logged without this timeline


@dataclass
class EntityData:
    """What one entity logged on timelines, one entry per row, in logging order.

    Attributes:
        times: timeline -> (N,) int64 (durations and timestamps in ns, sequences as they are; ``NO_TIME`` where
            a row was logged without that timeline).
        components: ``"Archetype:field"`` (e.g. ``"Scalars:scalars"``) -> N Python values (lists, dicts).
    """

    times: dict[str, np.ndarray]
    components: dict[str, list[Any]]

    def __len__(self) -> int:
        return len(next(iter(self.components.values()), []))

    def seconds(self, timeline: str) -> np.ndarray:
        """(N,) float64 seconds of a duration timeline."""
        return self.times[timeline].astype(np.float64) * 1e-9


def read_entity(path: str | Path, entity: str, *, recording: int = 0) -> EntityData:
    """The temporal rows of ``entity`` (e.g. ``"tactile/mbts/field"``) in the ``recording``-th recording.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the entity logged nothing on a timeline there.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "no such .rrd file", str(path))
    require_rerun("reading a .rrd file")
    entity = "/" + entity.strip("/")
    try:
        from rerun.chunk import RrdReader
    except ImportError:  # rerun-sdk before the chunk API
        table = _dataframe_table(path, entity)
    else:
        reader = RrdReader(path)
        stores = reader.recordings()
        if recording >= len(stores):
            raise ValueError(f"{path}: holds {len(stores)} recording(s), asked for number {recording}")
        batches = [c.to_record_batch() for c in reader.stream(store=stores[recording])
                   if c.entity_path == entity and not c.is_static and c.num_rows]
        table = _concat(batches)
    if table is None or table.num_rows == 0:
        raise ValueError(f"{path}: {entity} has no rows on a timeline")
    return _entity_data(table)


def _concat(batches: list):
    import pyarrow as pa

    if not batches:
        return None
    table = pa.Table.from_batches(batches) if len({b.schema for b in batches}) == 1 else \
        pa.concat_tables([pa.Table.from_batches([b]) for b in batches], promote_options="default")
    order = np.argsort(np.array(table.column(ROW_ID).to_pylist(), dtype=object), kind="stable")
    return table.take(order)  # row ids grow in logging order


def _entity_data(table) -> EntityData:
    import pyarrow as pa

    times, components = {}, {}
    for name in table.column_names:
        col = table.column(name)
        if name == ROW_ID or name == "log_time":
            continue
        if pa.types.is_duration(col.type) or pa.types.is_timestamp(col.type) or pa.types.is_integer(col.type):
            ints = col.cast(pa.int64()).fill_null(NO_TIME)
            times[name] = np.asarray(ints.to_numpy(zero_copy_only=False), dtype=np.int64)
        else:
            components[name] = col.to_pylist()
    return EntityData(times, components)


def _dataframe_table(path: Path, entity: str):  # rerun-sdk 0.24 (tested against 0.24.1)
    import rerun.dataframe as rdf

    rec = rdf.load_recording(str(path))
    names = [c.name for c in rec.schema().index_columns()]
    table = None
    # one row per index value: log_tick is unique per rr.log call; rows sent column-wise have none, and
    # take the frame number (unique per frame)
    for index in [n for n in ("log_tick", "frame") if n in names]:
        table = rec.view(index=index, contents=entity).select().read_all()
        if table.num_rows:
            break
    if table is None:
        return None
    prefix = entity + ":"
    table = table.rename_columns([n[len(prefix):] if n.startswith(prefix) else n for n in table.column_names])
    return table.drop_columns([n for n in ("log_tick",) if n in table.column_names])
