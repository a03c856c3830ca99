"""Decode a directory of captures into one Parquet dataset on a Dask cluster.

    python examples/dask_decode.py CAPTURES_DIR OUT [--force] [--workers 2]
    python examples/dask_decode.py CAPTURES_DIR OUT --scheduler tcp://HOST:8786

Without ``--scheduler`` it starts a ``LocalCluster`` (worker processes on this machine). With
it, the same code runs on a real cluster: every worker needs the package
(``pip install ./python``) and must see CAPTURES_DIR and OUT at the same paths (a shared
filesystem); OUT may be any path the workers can write.

Each capture is one task: ``aptscope.write_dataset(path, OUT, index)`` decodes it where it runs
and writes its part files, ``TABLE/part-<index>-<n>.parquet``, exactly as
``aptscope decode --to parquet -o OUT FILES…`` names them for the file at that position; so
the result equals the single-process command's, file for file and row for row, and no data
goes through the scheduler. A file that is not a capture (or cannot be read) is reported by
name and skipped.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Dict, List, Optional

import aptscope


def captures_in(directory: str) -> List[str]:
    """The files of ``directory``, sorted: their positions are their indices in the dataset."""
    return sorted(str(p) for p in Path(directory).iterdir() if p.is_file())


def decode_one(path: str, out: str, index: int) -> Dict[str, object]:
    """One task: decode ``path`` into ``out`` as input ``index``; errors become the result."""
    try:
        counts = aptscope.write_dataset(path, out, index)
        return {"file": path, "ok": True, **counts}
    except (aptscope.AptscopeError, OSError) as e:
        return {"file": path, "ok": False, "error": str(e)}


def decode_directory(client, files: List[str], out: str, force: bool = False) -> List[Dict[str, object]]:
    """Decode ``files`` into the dataset ``out`` with the Dask ``client``; one result per file."""
    aptscope.prepare_dataset(out, force)
    futures = client.map(decode_one, files, [out] * len(files), range(len(files)), pure=False)
    return client.gather(futures)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("captures")
    ap.add_argument("out")
    ap.add_argument("--force", action="store_true", help="replace an existing dataset")
    ap.add_argument("--scheduler", help="address of a running Dask scheduler")
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")
    a = ap.parse_args(argv)

    from dask.distributed import Client, LocalCluster

    files = captures_in(a.captures)
    if a.scheduler:
        client = Client(a.scheduler)
        cluster = None
    else:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, dashboard_address=None)
        client = Client(cluster)
    try:
        results = decode_directory(client, files, a.out, a.force)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    bad = [r for r in results if not r["ok"]]
    for r in bad:
        print(f"skipped {r['file']}: {r['error']}", file=sys.stderr)
    rows = sum(int(r["records"]) for r in results if r["ok"])
    print(f"{a.out}: {len(results) - len(bad)} of {len(results)} files, {rows} records")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
