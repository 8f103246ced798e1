"""Recording format benchmark: MCAP records as JSON with a JSON Schema per topic (what
``--record`` writes now, decodable by the mcap tools and Foxglove) against the msgpack records
with an empty schema it wrote before, on the same records.

Takes the records of a real recording (``sensornet run seed000 --record``), writes them both
ways (zstd chunks, as the recorder does) and reads them back, and prints the file size, the
write and read time per record, and their ratios (JSON / msgpack). Both read back to the same
records, which is checked.

    python benchmarks/bench_record_format.py runs/<time>-run        # every peer's recording
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a file: the repository root on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import msgpack  # noqa: E402
from sensornet.peers.recording import TOPICS, Recorder, read  # noqa: E402


def write_msgpack(path: Path, meta: dict, records: list) -> None:
    """The recorder before the schemas: msgpack records, an empty schema."""
    from mcap.writer import CompressionType, Writer

    with path.open("wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD)
        w.start(profile="", library="sensornet")
        schema = w.register_schema("sensornet.record", "", b"")
        ch = {t: w.register_channel(t, "msgpack", schema) for t in TOPICS}
        w.add_metadata("sensornet", meta)
        for seq, (topic, r) in enumerate(records, 1):
            t = max(0, int(r[0] * 1e9))
            w.add_message(ch[topic], t, msgpack.packb(r, use_bin_type=True), t, sequence=seq)
        w.finish()


def write_json(path: Path, meta: dict, records: list) -> None:
    rec = Recorder(path, meta)
    call = {"receive": lambda r: rec.receive(r[0], r[1], r[2]),
            "liveliness": lambda r: rec.liveliness(r[0], r[1], r[2]),
            "tick": lambda r: rec.tick(r[0]), "finish": lambda r: rec.finish(r[0]),
            "tracks": lambda r: rec.tracks(r[0], r[1], r[2])}
    for topic, r in records:
        call[topic](r)
    rec.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a run folder with record/*.mcap")
    ap.add_argument("--repeat", type=int, default=5, help="writes and reads timed (median)")
    args = ap.parse_args(argv)
    files = sorted(Path(args.run, "record").glob("*.mcap"))
    if not files:
        print(f"no recordings in {args.run}/record (make one with: sensornet run seed000 "
              "--record)", file=sys.stderr)
        return 2
    totals = {"msgpack": [0, 0.0, 0.0], "json": [0, 0.0, 0.0]}
    n = 0
    with tempfile.TemporaryDirectory() as tmp:
        for f in files:
            meta, records = read(f)
            n += len(records)
            for name, writer in (("msgpack", write_msgpack), ("json", write_json)):
                out = Path(tmp) / f"{name}.mcap"
                w, r = [], []
                for _ in range(args.repeat):
                    t0 = time.perf_counter()
                    writer(out, meta, records)
                    w.append(time.perf_counter() - t0)
                    t0 = time.perf_counter()
                    back = read(out)[1]
                    r.append(time.perf_counter() - t0)
                if back != records:
                    print(f"{name}: {f.name} did not read back to the same records")
                    return 1
                totals[name][0] += out.stat().st_size
                totals[name][1] += sorted(w)[len(w) // 2]
                totals[name][2] += sorted(r)[len(r) // 2]
    print(f"{len(files)} recordings, {n} records")
    print("| format | bytes | write us/record | read us/record |")
    print("|---|---:|---:|---:|")
    for name, (size, w, r) in totals.items():
        print(f"| {name} | {size} | {w / n * 1e6:.1f} | {r / n * 1e6:.1f} |")
    (sm, wm, rm), (sj, wj, rj) = totals["msgpack"], totals["json"]
    print(f"json / msgpack: size {sj / sm:.2f}x, write {wj / wm:.2f}x, read {rj / rm:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
