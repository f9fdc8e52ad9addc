#!/usr/bin/env python3
"""Writes fixed inputs for timing the store fuzzers, so a harness change can be measured on the same work.

libFuzzer's exec/s depends on what the corpus has grown into, so two campaigns do not compare two
harnesses; replaying one fixed set of inputs through each build does:

  python3 scripts/fuzz_bench_inputs.py /tmp/fz
  time BUILD/fuzz_store /tmp/fz/store/*          (libFuzzer runs each file once)
  time BUILD/fuzz_co_frames /tmp/fz/co_frames/*

fuzz_store inputs start by uploading, finishing and activating the seed image (half of them with the
HMAC key on, where the unsigned image is refused), then carry 100-2000 random operations: reboots,
which re-read the active slot, are the costly ones. fuzz_co_frames inputs are random operation
streams, a quarter of them image downloads of ~560 frames each. Inputs follow the decoders in
firmware_c/fuzz/fuzz_store.c and fuzz_co_frames.c.
"""
from __future__ import annotations

import random
import sys
from pathlib import Path

N_INPUTS = 200


def store_input(rng: random.Random) -> bytes:
    # the first byte is both the first operation (op % 11 == 0: begin) and the key switch (bit 7):
    # 0x84 = 132 = 12 * 11 is begin with the key on, 0x00 begin with it off; arg 1: the image's length
    first = 0x84 if rng.random() < 0.5 else 0x00
    upload = bytes([first, 1, 2, 0, 3, 0, 4, 0])  # begin(len), write all, finish, activate
    return upload + bytes(rng.randrange(256) for _ in range(2 * rng.randrange(100, 2000)))


def co_input(rng: random.Random) -> bytes:
    return bytes(rng.randrange(256) for _ in range(rng.randrange(16, 4096)))


def main(out: Path) -> None:
    rng = random.Random(1)
    for name, make in (("store", store_input), ("co_frames", co_input)):
        d = out / name
        d.mkdir(parents=True, exist_ok=True)
        for i in range(N_INPUTS):
            (d / f"{i:03d}").write_bytes(make(rng))
    print(f"{N_INPUTS} inputs each in {out}/store and {out}/co_frames")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "build/fuzz-bench-inputs"))
