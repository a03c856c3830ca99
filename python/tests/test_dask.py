"""The Dask example on a LocalCluster of 2 workers equals `aptscope decode --to parquet`."""

import importlib.util
import shutil
import subprocess
from pathlib import Path

import pyarrow.parquet as pq

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "dask_decode.py"


def load_example():
    spec = importlib.util.spec_from_file_location("dask_decode", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_local_cluster_equals_the_command(aptscope_bin, samples, tmp_path):
    from dask.distributed import Client, LocalCluster

    caps = tmp_path / "captures"
    caps.mkdir()
    for name in [
        "kdc101-session.pcapng",
        "kdc101-session.mcap",
        "kdc101-session.bin",
        "damaged.bin",
        "elliptec-bus.txt",
        "bsc203-rack.hex",
    ]:
        shutil.copy(samples / name, caps / name)
    (caps / "notes.bin").write_bytes(b"\x89PNG\r\n\x1a\n" + b"an image, not a capture " * 200)

    ex = load_example()
    files = ex.captures_in(str(caps))
    out = tmp_path / "dask"
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, Client(cluster) as client:
        results = ex.decode_directory(client, files, str(out))
        assert len(client.scheduler_info()["workers"]) == 2
    bad = [r for r in results if not r["ok"]]
    assert [Path(r["file"]).name for r in bad] == ["notes.bin"]
    assert "not a capture" in bad[0]["error"]

    ref = tmp_path / "cli"
    r = subprocess.run(
        [str(aptscope_bin), "decode", "--to", "parquet", "-o", str(ref), *files],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 1 and "skipped" in r.stderr and "notes.bin" in r.stderr, r.stderr

    parts = lambda d: sorted(str(p.relative_to(d)) for p in d.rglob("*.parquet"))
    assert parts(out) == parts(ref)
    assert len(parts(ref)) > 10
    for table in sorted({p.split("/")[0] for p in parts(ref)}):
        a = pq.read_table(ref / table)
        b = pq.read_table(out / table)
        # Row for row: the same rows in the same order (part files sort by input index).
        assert a.num_rows == b.num_rows and a.equals(b), table
    # The damaged capture's problems are in the diagnostics column of the one dataset.
    rec = pq.read_table(out / "records").to_pylist()
    assert any(r["diagnostics"] for r in rec if r["file"].endswith("damaged.bin"))
