"""The Python package against the command line: same records, same Parquet schema."""

import json
import random
import subprocess

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import aptscope


def cli(bin_, *args):
    r = subprocess.run([str(bin_), *args], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_decode_yields_the_ndjson_records(aptscope_bin, samples):
    path = samples / "kdc101-session.pcapng"
    got = list(aptscope.decode(path))
    want = [json.loads(l) for l in cli(aptscope_bin, "decode", "--json", str(path)).splitlines()]
    assert got == want
    names = [r.get("name") for r in got if r.get("type") == "frame"]
    assert "MOT_MOVE_HOME" in names


def same(a, b):
    """Equal and of the same types throughout (1 is not 1.0), with keys in the same order."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def test_every_sample_decodes_to_the_dicts_of_its_ndjson(aptscope_bin, samples):
    """The dicts are built in Rust without JSON text; they are what json.loads makes of the
    command's lines, record for record, on every sample (a file the command rejects, decode
    rejects too)."""
    files = sorted(
        p
        for d in (samples, samples / "sessions")
        for p in d.iterdir()
        if p.is_file() and p.suffix not in (".md", ".sh", ".py")
    )
    compared = 0
    for path in files:
        r = subprocess.run(
            [str(aptscope_bin), "decode", "--json", str(path)], capture_output=True, text=True
        )
        if r.returncode != 0:
            with pytest.raises((aptscope.AptscopeError, OSError)):
                list(aptscope.decode(path))
            continue
        want = [json.loads(l) for l in r.stdout.splitlines()]
        got = list(aptscope.decode(path))
        assert len(got) == len(want), path
        for g, w in zip(got, want):
            assert same(g, w), (path, g, w)
        compared += len(got)
    assert compared > 1000, compared


def test_decode_bytes_and_encode_round_trip():
    frame = aptscope.encode("MOT_MOVE_ABSOLUTE", chan_ident="CH1", absolute_position=4096)
    assert frame.hex() == "53040600d001" + "0100" + "00100000"
    (rec,) = [r for r in aptscope.decode(frame, proto="apt") if r["type"] == "frame"]
    assert rec["fields"] == {"chan_ident": "CH1", "absolute_position": 4096}
    ell = aptscope.encode("ma", dst="2", position=4096)
    assert ell == b"2ma00001000"
    (r,) = [r for r in aptscope.decode(ell + b"\r\n", proto="elliptec") if r["type"] == "frame"]
    assert r["name"] == "MOVE_ABSOLUTE" and r["fields"]["position"] == 4096


def test_errors_carry_the_diagnostic(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.bin"):
        list(aptscope.decode(tmp_path / "nope.bin"))
    with pytest.raises(aptscope.AptscopeError, match="proto"):
        list(aptscope.decode(b"", proto="canbus"))
    with pytest.raises(aptscope.EncodeError, match="absolute_positon"):
        aptscope.encode("MOT_MOVE_ABSOLUTE", absolute_positon=1)
    with pytest.raises(aptscope.EncodeError, match="MOT_MOVE_ABSOLUTLY"):
        aptscope.encode("MOT_MOVE_ABSOLUTLY")
    assert issubclass(aptscope.AptscopeError, ValueError)
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x89PNG\r\n\x1a\n" + b"just an image, not a capture. " * 100)
    out = tmp_path / "ds"
    aptscope.prepare_dataset(out)
    with pytest.raises(aptscope.AptscopeError, match="not a capture"):
        aptscope.write_dataset(junk, out, 0)
    with pytest.raises(aptscope.AptscopeError, match="--force"):
        aptscope.prepare_dataset(out)


def test_damaged_input_is_rows_with_diagnostics(samples):
    recs = list(aptscope.decode(samples / "damaged.bin"))
    assert any(r.get("diag") for r in recs)
    t = aptscope.to_arrow(samples / "damaged.bin")["records"]
    diags = t.column("diagnostics").to_pylist()
    assert any(diags)
    assert {"kind", "offset", "msg"} == set(next(d for d in diags if d)[0])


def test_to_arrow_has_the_parquet_schema(aptscope_bin, samples, tmp_path):
    path = str(samples / "kdc101-session.pcapng")
    out = tmp_path / "ds"
    cli(aptscope_bin, "decode", "--to", "parquet", "-o", str(out), path)
    tables = aptscope.to_arrow(path)
    on_disk = sorted(p.name for p in out.iterdir())
    assert sorted(tables) == on_disk
    for name, t in tables.items():
        disk = pq.read_table(out / name)
        assert t.schema.equals(disk.schema, check_metadata=True), name
        assert t.equals(disk), name
    st = tables["MOT_GET_DCSTATUSUPDATE"]
    assert st.schema.field("position").type == pa.int32()
    assert st.schema.field("position").metadata[b"quantity"] == b"pos"
    flags = [f for f in st.schema if f.metadata and b"flags" in f.metadata]
    assert flags and pa.types.is_list(flags[0].type)
    assert st.schema.field(flags[0].name + "_bits").type == pa.uint32()
    chan = st.column("chan_ident").to_pylist()
    assert set(chan) == {"CH1"} and set(st.column("chan_ident_code").to_pylist()) == {1}
    # Joins the records table on (file, n).
    rec = tables["records"].to_pandas()
    joined = st.to_pandas().merge(rec, on=["file", "n"])
    assert (joined["name"] == "MOT_GET_DCSTATUSUPDATE").all() and len(joined) == st.num_rows


def test_batches_are_the_tables_in_row_groups(samples):
    path = samples / "kdc101-session.pcapng"
    tables = aptscope.to_arrow(path)
    seen = {}
    for table, batch in aptscope.batches(path):
        assert isinstance(batch, pa.RecordBatch)
        assert batch.schema.equals(tables[table].schema, check_metadata=True), table
        seen.setdefault(table, []).append(batch)
    assert sorted(seen) == sorted(tables)
    # The records table first, the others as they first came; their batches are the chunks.
    assert list(tables) == ["records"] + [t for t in seen if t != "records"]
    for t, bs in seen.items():
        assert pa.Table.from_batches(bs).equals(tables[t]), t
        chunks = [len(c) for c in tables[t].column(0).chunks]
        assert chunks == [b.num_rows for b in bs], t
    # Bytes of one stream, and a missing file.
    frame = aptscope.encode("MOT_MOVE_ABSOLUTE", chan_ident=1, absolute_position=4096)
    got = dict(aptscope.batches(frame, proto="apt"))
    assert got["MOT_MOVE_ABSOLUTE"].column("absolute_position").to_pylist() == [4096]
    with pytest.raises(FileNotFoundError):
        list(aptscope.batches(samples / "nope.bin"))


def _spliced(samples, seed):
    """A session's frames repeated with random bytes between, cut at random places."""
    rng = random.Random(seed)
    frames = (samples / "kdc101-session.bin").read_bytes()
    out = bytearray()
    for _ in range(40):
        cut = rng.randrange(len(frames))
        out += frames[cut:] + bytes(rng.randrange(256) for _ in range(rng.randrange(20)))
        out += frames[:cut]
    return bytes(out)


@pytest.mark.parametrize(
    "source", ["kdc101-session.mcap", "elliptec-bus.txt", "damaged.bin", "spliced"]
)
def test_rows_built_on_threads_are_those_of_one(samples, monkeypatch, source):
    # Runs of 7 records: every sample is cut into many, handed to the threads in turn.
    monkeypatch.setenv("APTSCOPE_BATCH_RECORDS", "7")
    src = _spliced(samples, 11) if source == "spliced" else samples / source
    proto = "apt" if source == "spliced" else "auto"
    one = aptscope.to_arrow(src, proto, threads=1)
    n = one["records"].num_rows
    assert n > 7
    for threads in (2, 3):
        many = aptscope.to_arrow(src, proto, threads=threads)
        assert sorted(many) == sorted(one)
        for t in one:
            assert many[t].schema.equals(one[t].schema, check_metadata=True), t
            assert many[t].equals(one[t]), t
    # A batch of each table per run it has rows in: the records table one per run.
    records = [b.num_rows for t, b in aptscope.batches(src, proto, threads=2) if t == "records"]
    assert records == [7] * (n // 7) + ([n % 7] if n % 7 else [])


def test_only_the_tables_asked_for(samples):
    path = samples / "kdc101-session.pcapng"
    tables = aptscope.to_arrow(path)
    kind = "MOT_GET_DCSTATUSUPDATE"
    for want in (["records"], [kind], ["records", kind]):
        got = aptscope.to_arrow(path, tables=want)
        assert sorted(got) == sorted(want)
        for t in want:
            assert got[t].equals(tables[t]), t
            assert got[t].schema.equals(tables[t].schema, check_metadata=True), t
    assert {t for t, _ in aptscope.batches(path, tables=(kind,))} == {kind}
    # A kind not in the capture: no table; a name that is no table: an error.
    assert aptscope.to_arrow(path, tables=["ELL_GET_STATUS"]) == {}
    with pytest.raises(aptscope.AptscopeError, match="MOT_NO_SUCH"):
        aptscope.to_arrow(path, tables=["MOT_NO_SUCH"])


def test_an_empty_capture_has_an_empty_records_table(samples, tmp_path):
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    full = aptscope.to_arrow(samples / "kdc101-session.pcapng", tables=["records"])["records"]
    for threads in (1, 2):
        got = aptscope.to_arrow(empty, threads=threads)
        assert sorted(got) == ["records"]
        assert got["records"].num_rows == 0
        assert got["records"].schema.equals(full.schema, check_metadata=True)
    assert list(aptscope.batches(empty)) == []
    assert aptscope.to_arrow(empty, tables=["MOT_GET_DCSTATUSUPDATE"]) == {}


def test_batches_stream_into_duckdb(samples):
    # Imported here, not skipped when missing: python/run-tests installs it, and a test that
    # passes by skipping would hide a broken environment.
    import duckdb

    path = samples / "kdc101-session.pcapng"
    con = duckdb.connect()
    made = set()
    for table, batch in aptscope.batches(path):
        if table != "MOT_GET_DCSTATUSUPDATE":
            continue
        con.register("b", batch)
        if table in made:
            con.execute("INSERT INTO st SELECT * FROM b")
        else:
            con.execute("CREATE TABLE st AS SELECT * FROM b")
            made.add(table)
        con.unregister("b")
    st = aptscope.to_arrow(path)["MOT_GET_DCSTATUSUPDATE"]
    n, lo, hi = con.execute("SELECT count(*), min(position), max(position) FROM st").fetchone()
    pos = st.column("position").to_pylist()
    assert (n, lo, hi) == (st.num_rows, min(pos), max(pos))


def test_write_dataset_equals_the_command(aptscope_bin, samples, tmp_path):
    files = [str(samples / "kdc101-session.bin"), str(samples / "elliptec-bus.txt")]
    a, b = tmp_path / "cli", tmp_path / "py"
    cli(aptscope_bin, "decode", "--to", "parquet", "-o", str(a), *files)
    aptscope.prepare_dataset(b)
    counts = [aptscope.write_dataset(f, b, i) for i, f in enumerate(files)]
    assert all(c["records"] > 0 for c in counts)
    parts = lambda d: sorted(str(p.relative_to(d)) for p in d.rglob("*.parquet"))
    assert parts(a) == parts(b)
    for p in parts(a):
        assert pq.read_table(a / p).equals(pq.read_table(b / p)), p
