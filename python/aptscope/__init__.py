"""Decode Thorlabs APT and Elliptec serial captures from Python.

aptscope's Rust decoder, as a package:

* :func:`decode` yields every record of a capture as a dict (the NDJSON shape of
  ``aptscope decode --json``, documented in docs/ndjson.md);
* :func:`to_arrow` returns pyarrow tables with exactly the schema of
  ``aptscope decode --to parquet`` (README "Parquet output"): ``records`` and one table per
  message kind, typed from the message tables;
* :func:`batches` yields the same tables' record batches as the capture is decoded, for
  captures larger than memory (pandas, Polars, DuckDB read them one at a time);
* :func:`write_dataset` adds one capture to a Parquet dataset directory, as the command does
  (for running many captures on a cluster, see ``examples/dask_decode.py``);
* :func:`encode` builds a message's bytes.

Errors raise :class:`AptscopeError` (a ``ValueError``) or ``FileNotFoundError`` with the
diagnostic; damaged input is not an error: its problems are in each record's diagnostics.

>>> import aptscope
>>> frame = aptscope.encode("MOT_MOVE_ABSOLUTE", chan_ident=1, absolute_position=4096)
>>> [r["name"] for r in aptscope.decode(frame, proto="apt")]
['MOT_MOVE_ABSOLUTE']
"""

from __future__ import annotations

import os
from typing import Any, Dict, Iterable, Iterator, Optional, Tuple, Union

from . import _aptscope
from ._aptscope import AptscopeError, EncodeError

__all__ = [
    "AptscopeError",
    "EncodeError",
    "batches",
    "decode",
    "encode",
    "prepare_dataset",
    "to_arrow",
    "write_dataset",
]

Source = Union[bytes, bytearray, memoryview, str, "os.PathLike[str]"]


def _src(source: Source) -> Any:
    if isinstance(source, (bytearray, memoryview)):
        return bytes(source)
    return source


def decode(source: Source, proto: str = "auto") -> Iterator[Dict[str, Any]]:
    """Yield the records of a capture, one dict each, as they are decoded.

    ``source`` is a capture file's path (any format ``aptscope decode`` reads: pcapng, pcap,
    MCAP, serial logs, hex text, raw bytes) or the bytes of one serial stream. ``proto`` is
    ``"auto"`` (detected from the first 4 KiB), ``"apt"`` or ``"elliptec"``.

    Each dict is one NDJSON record: frames (``type == "frame"``, with ``n``, ``name``,
    ``fields``, ``pair``, ``latency_ms``, ``diag`` …), garbage runs, requests without reply,
    input diagnostics and the protocol detection.

    Raises ``FileNotFoundError`` for a missing file and :class:`AptscopeError` for an input it
    cannot open or a bad ``proto``.
    """
    # The dicts are built in Rust from the decoded records: no JSON text in between.
    yield from _aptscope.Records(_src(source), proto)


def to_arrow(
    source: Source,
    proto: str = "auto",
    name: Optional[str] = None,
    tables: Optional[Iterable[str]] = None,
    threads: Optional[int] = None,
) -> Dict[str, Any]:
    """Decode a capture into pyarrow tables: ``{"records": …, "MOT_MOVE_ABSOLUTE": …}``.

    The tables have exactly the schemas of ``aptscope decode --to parquet``: ``records``
    (common columns) and one table per message kind present, whose columns are the message's
    fields (integers as integers, enums as the label with ``<field>_code`` beside, flags as
    lists of names with ``<field>_bits``, units in the field metadata). ``name`` is the value of
    the ``file`` column (default: the path, or ``"<bytes>"``).

    ``tables`` names the tables wanted (``["records"]``, ``["MOT_GET_DCSTATUSUPDATE"]`` …;
    default: all): the others are not built at all, which makes decoding faster (about twice
    for ``records`` alone on a stream of status updates). A name that is neither ``records``
    nor a message kind raises :class:`AptscopeError`; a kind absent from the capture is absent
    from the result, ``records`` never is (a capture with no record, an empty file, gives it
    with no rows).

    ``threads``: the threads that build the rows (default: one per core; ``1``: all on the
    calling thread). The tables are the same whatever it is.
    """
    import pyarrow as pa

    wanted = None if tables is None else list(tables)
    # Each table's batches cross as one Arrow C stream (its schema once); a capture with no
    # record (an empty file) still has its records table, empty.
    got = _aptscope.tables(_src(source), proto, name, wanted, threads)
    return {t: pa.RecordBatchReader.from_stream(s).read_all() for t, s in got}


def batches(
    source: Source,
    proto: str = "auto",
    name: Optional[str] = None,
    tables: Optional[Iterable[str]] = None,
    threads: Optional[int] = None,
) -> Iterator[Tuple[str, Any]]:
    """Yield ``(table, pyarrow.RecordBatch)`` pairs as the capture is decoded.

    The tables and schemas are those of :func:`to_arrow` (and of ``aptscope decode --to
    parquet``; ``tables`` and ``threads`` as there); a table's batches, one after the other,
    are its rows in order, each batch at most a row group (65,536 rows). The capture is decoded
    on the calling thread and its records handed, in runs growing from 8,192 to 65,536, to the
    threads that build the rows (``threads=1``: on the calling thread, each batch then one row group of the
    Parquet output); batches are yielded as they are built, so memory stays bounded whatever
    the capture's size. The columns cross from Rust through the Arrow C data interface (the
    PyCapsule protocol): no copy, no Parquet or JSON in between.

    >>> import aptscope, duckdb                                      # doctest: +SKIP
    >>> con = duckdb.connect()
    >>> for table, batch in aptscope.batches("capture.pcapng"):
    ...     if table == "MOT_GET_DCSTATUSUPDATE":
    ...         con.register("b", batch)
    ...         con.execute("INSERT INTO pos SELECT ts_ns, position FROM b")
    """
    import pyarrow as pa

    wanted = None if tables is None else list(tables)
    for table, batch in _aptscope.Batches(_src(source), proto, name, wanted, threads):
        yield table, pa.record_batch(batch)


def prepare_dataset(out: Union[str, "os.PathLike[str]"], force: bool = False) -> None:
    """Create the dataset directory ``out``; with ``force`` replace an earlier dataset there.

    Raises :class:`AptscopeError` when ``out`` exists (without ``force``) or is a directory
    that is not an aptscope dataset.
    """
    _aptscope.prepare_dataset(out, force)


def write_dataset(
    path: Union[str, "os.PathLike[str]"],
    out: Union[str, "os.PathLike[str]"],
    index: int,
    proto: str = "auto",
    name: Optional[str] = None,
) -> Dict[str, int]:
    """Decode capture ``path`` into the dataset directory ``out`` as input number ``index``.

    Writes the part files ``TABLE/part-<index>-<n>.parquet`` exactly as
    ``aptscope decode --to parquet -o out FILES…`` does for the file at that position, so
    captures can be decoded anywhere (threads, processes, cluster workers) into one dataset.
    ``name`` is the ``file`` column's value (default: ``path`` as given). Returns counts
    (``records``, ``frames``, ``diagnostics``, ``row_groups``).

    Raises :class:`AptscopeError` for a file that is not a capture (nothing is written).
    """
    return _aptscope.write_dataset(path, out, index, proto, name)


def encode(
    name: str,
    *,
    dst: Optional[str] = None,
    src: Optional[str] = None,
    form: Optional[str] = None,
    sub: Optional[str] = None,
    **fields: Any,
) -> bytes:
    """The bytes of APT message ``name`` (or Elliptec command, by name or mnemonic) with ``fields``.

    Values are numbers, enum labels or flag names (``chan_ident="CH1"``); lists become
    comma-separated values. ``dst``/``src`` are addresses (``"usb"``, ``"bay1"``, ``"0x50"``;
    for Elliptec the module address ``"0"``–``"F"``); ``form`` picks a form (``"hdr"`` or a
    data length) and ``sub`` a sub-message. Fields not given are 0.

    Raises :class:`EncodeError` naming the unknown message, field or value.
    """
    pairs = []
    for k, v in fields.items():
        if isinstance(v, (list, tuple)):
            v = ",".join(str(x) for x in v)
        elif isinstance(v, bool):
            v = int(v)
        pairs.append((k, str(v)))
    return _aptscope.encode(name, pairs, dst, src, form, sub)
