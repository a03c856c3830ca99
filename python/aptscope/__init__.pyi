"""Type stubs of the aptscope package (see ``__init__.py`` for the documentation)."""

import os
from typing import Any, Dict, Iterable, Iterator, Optional, Tuple, Union

import pyarrow

Source = Union[bytes, bytearray, memoryview, str, os.PathLike[str]]
PathArg = Union[str, os.PathLike[str]]

class AptscopeError(ValueError):
    """An input aptscope cannot decode, or arguments it cannot use; the message is the diagnostic."""

class EncodeError(AptscopeError):
    """A message that cannot be encoded: unknown name, field or value."""

def decode(source: Source, proto: str = "auto") -> Iterator[Dict[str, Any]]:
    """Yield the records of a capture (a path, or the bytes of one serial stream), one dict each."""

def to_arrow(
    source: Source,
    proto: str = "auto",
    name: Optional[str] = None,
    tables: Optional[Iterable[str]] = None,
    threads: Optional[int] = None,
) -> Dict[str, pyarrow.Table]:
    """Decode a capture into pyarrow tables with the schemas of ``aptscope decode --to parquet``."""

def batches(
    source: Source,
    proto: str = "auto",
    name: Optional[str] = None,
    tables: Optional[Iterable[str]] = None,
    threads: Optional[int] = None,
) -> Iterator[Tuple[str, pyarrow.RecordBatch]]:
    """Yield ``(table, record batch)`` pairs of :func:`to_arrow`'s tables as the capture is decoded."""

def prepare_dataset(out: PathArg, force: bool = False) -> None:
    """Create the dataset directory ``out``; with ``force`` replace an earlier dataset there."""

def write_dataset(
    path: PathArg,
    out: PathArg,
    index: int,
    proto: str = "auto",
    name: Optional[str] = None,
) -> Dict[str, int]:
    """Decode capture ``path`` into dataset ``out`` as input number ``index``; returns counts."""

def encode(
    name: str,
    *,
    dst: Optional[str] = None,
    src: Optional[str] = None,
    form: Optional[str] = None,
    sub: Optional[str] = None,
    **fields: Any,
) -> bytes:
    """The bytes of an APT message or Elliptec command with ``fields``."""
