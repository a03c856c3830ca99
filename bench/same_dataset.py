"""Whether two Parquet datasets of `aptscope decode --to parquet` hold the same tables.

Usage: python bench/same_dataset.py DATASET_A DATASET_B

For every table (directory) of either: the same Arrow schema (names, types, nullability and
field metadata) and the same rows in the same order (part files read in name order). Row
groups may be cut differently: the rows are compared, not the files. Exits 1 and names the
first difference otherwise. Needs pyarrow.
"""
import os
import sys

import pyarrow as pa
import pyarrow.parquet as pq


def tables(root):
    return sorted(
        d for d in os.listdir(root) if os.path.isdir(os.path.join(root, d))
    )


def read(root, table):
    d = os.path.join(root, table)
    parts = sorted(f for f in os.listdir(d) if f.endswith(".parquet"))
    ts = [pq.read_table(os.path.join(d, f)) for f in parts]
    return pa.concat_tables(ts) if ts else None


def main(a, b):
    ta, tb = tables(a), tables(b)
    if ta != tb:
        print(f"tables differ: only in A {sorted(set(ta) - set(tb))}, only in B {sorted(set(tb) - set(ta))}")
        return 1
    rows = 0
    for t in ta:
        x, y = read(a, t), read(b, t)
        if not x.schema.equals(y.schema, check_metadata=True):
            print(f"{t}: schemas differ\nA: {x.schema}\nB: {y.schema}")
            return 1
        if x.num_rows != y.num_rows:
            print(f"{t}: {x.num_rows} rows against {y.num_rows}")
            return 1
        if not x.equals(y):
            for c in x.column_names:
                if not x[c].equals(y[c]):
                    xc, yc = x[c].combine_chunks(), y[c].combine_chunks()
                    i = next(i for i in range(len(xc)) if xc[i] != yc[i])
                    print(f"{t}.{c}: row {i}: {xc[i]} against {yc[i]}")
                    return 1
            print(f"{t}: tables differ")
            return 1
        rows += x.num_rows
    print(f"same: {len(ta)} tables, {rows} rows")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
