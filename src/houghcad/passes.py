"""The machinery of the pipeline's passes: what a pass reads, how passes are
declared, run, timed and traced. The passes themselves are in
:mod:`houghcad.pipeline`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from .associate import Associator
from .context import Context
from .families import Family
from .state import Segmentation

PAPER_5_2 = "paper §5.2"
PAPER_5_3 = "paper §5.3"
PAPER_5_4 = "paper §5.4"
EXTENSION = "extension"
# Progress fractions reported as the passes run (the splitting phase reports
# within its own span, see houghcad.pipeline).
_PASSES_START = 0.1
_PASSES_SPAN = 0.85
_PASSES_END = 0.95


def quiet(stage: str, fraction: float) -> None:
    """Progress that reports nothing (module-level: a fitted Segmenter keeps its run, and a
    lambda would not pickle)."""


@dataclass(frozen=True)
class Run:
    """What the passes read besides the state.

    Attributes
    ----------
    ctx : Context
        Scales and thresholds of the run.
    families : list of Family
        The selected families.
    voted : list of Family
        Those voted in recognition (a family refining a selected one is
        offered its base's segments instead, see :func:`refine_pass`).
    associator : Associator
    progress : callable
        ``progress(stage, fraction)``.
    """

    ctx: Context
    families: list[Family]
    voted: list[Family]
    associator: Associator
    progress: Callable[[str, float], None] = quiet


PassFn = Callable[[Segmentation, Run], Segmentation]


def always(ctx: Context) -> bool:
    return True


@dataclass(frozen=True)
class Pass:
    """A named step over the state.

    ``when(ctx)`` decides whether it runs. ``after`` are follow-up passes, run
    after it (always, or with ``only_if_changed`` only when it wrote to the
    state); they are timed as ``name.follow_up``.
    """

    name: str
    run: PassFn
    source: str
    when: Callable[[Context], bool] = always
    after: tuple["Pass", ...] = ()
    only_if_changed: bool = False


#: ``trace(step, name, state)``: called after every pass that ran.
TraceFn = Callable[[int, str, Segmentation], None]


@dataclass
class Runner:
    """Runs passes in order, timing each and tracing the state after it."""

    run: Run
    timing: dict[str, float] = field(default_factory=dict)
    trace: TraceFn | None = None
    check: bool = False
    total: int = 1
    skip: frozenset[str] = frozenset()
    step: int = 0

    def __call__(self, p: Pass, seg: Segmentation, prefix: str = "") -> Segmentation:
        name = prefix + p.name
        if not p.when(self.run.ctx) or name in self.skip:
            return seg
        self.run.progress(name, min(_PASSES_START + _PASSES_SPAN * self.step / self.total, _PASSES_END))
        before = seg.version
        t = time.perf_counter()
        seg = p.run(seg, self.run)
        self.timing[name] = self.timing.get(name, 0.0) + time.perf_counter() - t
        self.step += 1
        if self.check:
            seg.check()
        if self.trace is not None:
            self.trace(self.step, name, seg)
        if p.after and (seg.version != before or not p.only_if_changed):
            for q in p.after:
                seg = self(q, seg, name + ".")
        return seg


def monotonic(progress: Callable[[str, float], None] | None) -> Callable[[str, float], None]:
    """``progress`` with fractions that never go back (passes after the
    splitting phase report below where its own progress reached)."""
    if progress is None:
        return quiet
    last = [0.0]

    def report(stage: str, fraction: float) -> None:
        last[0] = max(last[0], float(fraction))
        progress(stage, last[0])

    return report
