"""Speed of to_arrow() and of batches() into DuckDB:
`python arrow_speed.py CAPTURE [to_arrow|chain|duckdb] [THREADS]`.

Prints records, CPU seconds (this process), wall seconds, records per CPU-second and per
second of wall time, the page faults of the call (each page of memory it touched first) and
peak RSS. THREADS is to_arrow()'s and batches()' (default: one per core).
The chain mode is to_arrow() asked for no table: reading, framing, decoding, pairing,
numbering and units, the sequential decode chain, with no row built (its records are counted
by a second call, not timed): the bound of a call whose chain runs on one thread.
The DuckDB mode streams every table's batches into a DuckDB table of its name, as a notebook
streaming a capture larger than memory would.
"""
import sys, time, resource
import aptscope, pyarrow as pa
path = sys.argv[1]
what = sys.argv[2] if len(sys.argv) > 2 else "to_arrow"
threads = int(sys.argv[3]) if len(sys.argv) > 3 else None
t0, w0 = time.process_time(), time.perf_counter()
faults0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
if what == "chain":
    tables = aptscope.to_arrow(path, threads=threads, tables=[])
    extra = f"{len(tables)} tables"
elif what == "to_arrow":
    tables = aptscope.to_arrow(path, threads=threads)
    n = tables["records"].num_rows
    extra = f"{len(tables)} tables"
else:
    import duckdb
    con = duckdb.connect()
    made = set()
    n = 0
    for table, batch in aptscope.batches(path, threads=threads):
        if table == "records":
            n += batch.num_rows
        con.register("b", batch)
        t = '"' + table + '"'
        if table in made:
            con.execute(f"INSERT INTO {t} SELECT * FROM b")
        else:
            con.execute(f"CREATE TABLE {t} AS SELECT * FROM b")
            made.add(table)
        con.unregister("b")
    extra = f"{con.execute('SELECT count(*) FROM records').fetchone()[0]} rows in duckdb records"
# (At least a microsecond: an empty capture's call may take less than the clocks tell.)
cpu, wall = (max(x, 1e-6) for x in (time.process_time() - t0, time.perf_counter() - w0))
use = resource.getrusage(resource.RUSAGE_SELF)
faults, rss = use.ru_minflt - faults0, use.ru_maxrss / 1024
if what == "chain":
    n = aptscope.to_arrow(path, threads=threads, tables=["records"])["records"].num_rows
print(f"{what}: {n} records, {extra}: {cpu:.3f} CPU-s, {wall:.3f} s wall, {n/cpu/1e6:.2f} M records per CPU-s, {n/wall/1e6:.2f} M per second, {faults} page faults, peak {rss:.0f} MiB")
