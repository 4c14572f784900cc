"""Timing helpers shared by the benchmarks (``lfcl bench ...``).

Every figure the benchmarks report is a *median* of wall-clock times taken with
:func:`time.perf_counter`. Device work is bracketed by ``queue.finish()`` on both
sides, so a time covers the enqueue, the kernel and nothing queued before it.

Example::

    >>> from lfcl.bench.timing import time_calls, parse_size
    >>> timing = time_calls(lambda: sum(range(1000)), repeats=3, warmup=1)
    >>> len(timing.times), timing.median > 0
    (3, True)
    >>> parse_size("4500x4500", "--size")
    (4500, 4500)
"""

from __future__ import annotations

import dataclasses
import statistics
import time
from collections.abc import Callable


@dataclasses.dataclass
class Timing:
    """Wall-clock seconds of each timed call (warm-up calls excluded)."""

    times: list[float]

    @property
    def median(self) -> float:
        return float(statistics.median(self.times))

    @property
    def best(self) -> float:
        return float(min(self.times))


def time_calls(fn: Callable[[], object], repeats: int, warmup: int = 1,
               sync: Callable[[], object] | None = None) -> Timing:
    """Call ``fn`` ``warmup`` times untimed, then ``repeats`` times timed.

    ``sync`` (e.g. ``queue.finish``) is called before starting and after each
    call, inside the timed interval, so asynchronous device work is counted.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    for _ in range(max(warmup, 0)):
        fn()
        if sync is not None:
            sync()
    times = []
    for _ in range(repeats):
        if sync is not None:
            sync()
        start = time.perf_counter()
        fn()
        if sync is not None:
            sync()
        times.append(time.perf_counter() - start)
    return Timing(times)


def gb_per_s(nbytes: int, seconds: float) -> float:
    """Bandwidth in GB/s (10^9 bytes per second)."""
    return nbytes / seconds / 1e9 if seconds > 0 else float("inf")


def parse_size(text: str, name: str) -> tuple[int, int]:
    """``"HxW"`` (or ``"N"`` for NxN) -> ``(H, W)``, positive integers; else a ``ValueError``."""
    parts = str(text).lower().replace("×", "x").split("x")
    try:
        numbers = [int(p.strip()) for p in parts]
    except ValueError:
        raise ValueError(f"malformed {name} {text!r}: expected HxW, e.g. 4500x4500") from None
    if len(numbers) == 1:
        numbers *= 2
    if len(numbers) != 2 or min(numbers) < 1:
        raise ValueError(f"malformed {name} {text!r}: expected two positive integers HxW")
    return numbers[0], numbers[1]


def parse_ints(text: str, name: str) -> list[int]:
    """``"1,2,5"`` -> ``[1, 2, 5]`` (positive, sorted, unique); else a ``ValueError``."""
    try:
        values = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{name} must be comma-separated positive integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise ValueError(f"{name} must be comma-separated positive integers, got {text!r}")
    return sorted(set(values))


def format_table(headers: list[str], rows: list[list[str]], align: str | None = None) -> str:
    """A Markdown table; ``align`` is one character per column, 'l' or 'r' (default: l then r)."""
    align = align or "l" + "r" * (len(headers) - 1)
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) if rows else len(str(h))
              for i, h in enumerate(headers)]

    def line(cells):
        padded = [str(c).ljust(w) if a == "l" else str(c).rjust(w) for c, w, a in zip(cells, widths, align)]
        return "| " + " | ".join(padded) + " |"

    rule = "|" + "|".join(("-" * (w + 1) + ":") if a == "r" else ("-" * (w + 2)) for w, a in zip(widths, align)) + "|"
    return "\n".join([line(headers), rule] + [line(r) for r in rows])


def add_capture_arguments(parser, methods: str) -> None:
    """The options that say which simulated captures a scene benchmark runs on (``--lenses``,
    ``--scenes`` (with ``--texture``) or ``--lightfield``, ``--lux``, ``--seed``) and ``--methods`` (default ``methods``)."""
    parser.add_argument("--lenses", default="64,160",
                        help="lenses per side, comma-separated; 'full' (with --lightfield): the whole light field")
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--lightfield", default=None, metavar="PATH",
                        help="a rendered or decoded light field (HCI-layout folder or .npy, 9x9 views) to simulate "
                             "raws from, instead of --scenes")
    parser.add_argument("--texture", default=None, metavar="IMAGES",
                        help="images (comma-separated; anything OpenImageIO reads, or a camera raw) mapped onto the "
                             "planes of every --scenes scene, one capture per image (lfcl simulate --texture)")
    parser.add_argument("--lux", default="2,12,50")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", default=methods)


def captures(args):
    """(lenses, scene, lux, capture) for every capture :func:`add_capture_arguments` names, in memory."""
    from ..evaluation.evaluate import simulated_capture

    textures = args.texture.split(",") if args.texture else [None]
    if args.lightfield and textures != [None]:
        raise SystemExit("--texture maps images onto the built-in scenes' planes; a --lightfield has none")
    for lenses in (None if v == "full" else int(v) for v in args.lenses.split(",")):
        if lenses is None and not args.lightfield:
            raise SystemExit("--lenses full needs --lightfield: a built-in scene has no full frame")
        for scene in [args.lightfield] if args.lightfield else args.scenes.split(","):
            for texture in textures:
                for lux in (float(v) for v in args.lux.split(",")):
                    yield lenses, scene, lux, simulated_capture(lenses, lux, args.seed, scene, args.lightfield,
                                                                texture)
