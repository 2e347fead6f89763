#!/usr/bin/env python3
"""Fuzz the UBX/NMEA stream decoder with random and mutated byte strings.

Each case builds a byte string from 1-4 pieces (random bytes, truncated, bit-flipped or
spliced frames of the recorded u-blox stream, or intact frames), feeds it to a fresh
`Decoder` in random-sized chunks, then appends a flush and a known NMEA sentence that must
decode.  Prints how many cases ran, exceptions that escaped (must be 0), cases whose
trailing sentence failed to decode (must be 0), byte-accounting violations (must be 0) and
the decoder's totals.

Usage:  .venv/bin/python bench/fuzz_gnss_stream.py [--cases N] [--seed S] [--data PATH]
"""
import argparse
import random
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

from ins_gnss_ros.gnss.observations import NmeaHeading
from ins_gnss_ros.gnss.stream import Decoder, split_frames

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "walk_0827" / "gnss_1730.ubx"


def nmea(sentence):
    """A complete NMEA sentence with its checksum."""
    value = 0
    for byte in sentence.encode():
        value ^= byte
    return f"${sentence}*{value:02X}\r\n".encode()


def make_case(rng, frames):
    pieces = []
    for _ in range(rng.randint(1, 4)):
        kind = rng.choice(("random", "truncated", "flipped", "spliced", "intact"))
        frame = rng.choice(frames)
        if kind == "random":
            pieces.append(rng.randbytes(rng.randint(0, 300)))
        elif kind == "truncated":
            pieces.append(frame[:rng.randint(0, len(frame) - 1)])
        elif kind == "flipped":
            mutated = bytearray(frame)
            for _ in range(rng.randint(1, 6)):
                mutated[rng.randrange(len(mutated))] ^= 1 << rng.randrange(8)
            pieces.append(bytes(mutated))
        elif kind == "spliced":
            other = rng.choice(frames)
            pieces.append(frame[:rng.randint(0, len(frame))] + other[rng.randint(0, len(other)):])
        else:
            pieces.append(frame)
    return b"".join(pieces)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=20250828)
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    if not args.data.exists():
        print(f"recorded stream {args.data} not found", file=sys.stderr)
        return 2
    frames = split_frames(args.data.read_bytes(), 3000)
    rng = random.Random(args.seed)
    marker = nmea("GNHDT,42.0,T")
    flush = bytes(4200)
    totals = Counter()
    escaped = not_recovered = unaccounted = 0
    start = time.perf_counter()
    for _ in range(args.cases):
        blob = make_case(rng, frames)
        decoder = Decoder(max_ubx_payload=4096)
        try:
            pos = 0
            while pos < len(blob):
                step = rng.randint(1, 512)
                decoder.feed(blob[pos:pos + step])
                pos += step
            records = decoder.feed(flush + marker)
        except Exception:  # the point of the benchmark: count anything that escapes
            escaped += 1
            if escaped <= 3:
                traceback.print_exc()
            continue
        if not records or not isinstance(records[-1], NmeaHeading):
            not_recovered += 1
        s = decoder.stats
        if s["frame_bytes"] + s["garbage_bytes"] + decoder.buffered != s["bytes_in"]:
            unaccounted += 1
        for key in ("bytes_in", "frames_ok", "garbage_bytes", "checksum_errors", "unknown",
                    "malformed", "records"):
            totals[key] += s[key]
    elapsed = time.perf_counter() - start
    print(f"cases                 {args.cases}")
    print(f"seed                  {args.seed}")
    print(f"exceptions escaped    {escaped}")
    print(f"trailing frame lost   {not_recovered}")
    print(f"byte accounting wrong {unaccounted}")
    for key, value in totals.items():
        print(f"{key:<21} {value}")
    print(f"elapsed               {elapsed:.1f} s ({1e6 * elapsed / args.cases:.0f} us/case)")
    return 0 if escaped == not_recovered == unaccounted == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
