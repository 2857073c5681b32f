"""Build progress: one overall fraction from the server's per-phase fractions, and a tqdm bar.

The server reports the current phase and the fraction done of that phase. The overall fraction
weighs the phases by their typical share of a build's time (PHASE_WEIGHTS, measured on this
project's builds, see below); it is an estimate that drives the bar and its ETA, not a promise.
"""

import sys

from ._stubs import pb

# Typical shares of a build's wall time, measured with fieldspaced --threads 2 on 2 cores: vector
# d = 500 on a 20,480-face icosphere (1.7 s), and vector d = 1000, tensor d = 600 and 4-field
# d = 800 on the 49,152-face demo mesh (2.5-4.1 s). The local eigenproblems dominate (65-77 %).
# Time spent queued behind other builds is unknown in advance and counts as 0.
PHASE_WEIGHTS = (
    (pb.BUILD_PHASE_QUEUED, 0.0),
    (pb.BUILD_PHASE_OPERATOR, 0.02),
    (pb.BUILD_PHASE_SAMPLING, 0.015),
    (pb.BUILD_PHASE_REGIONS, 0.025),
    (pb.BUILD_PHASE_EIGENSOLVE, 0.71),
    (pb.BUILD_PHASE_ASSEMBLY, 0.08),
    (pb.BUILD_PHASE_PRECOMPUTE, 0.115),
    (pb.BUILD_PHASE_SAVING, 0.035),
)
_BEFORE = {}
_WEIGHT = {}
_total = 0.0
for _phase, _w in PHASE_WEIGHTS:
    _BEFORE[_phase] = _total
    _WEIGHT[_phase] = _w
    _total += _w
del _phase, _w


def overall_fraction(phase, fraction):
    """The estimated fraction of the whole build done, in [0, 1]."""
    if phase == pb.BUILD_PHASE_DONE:
        return 1.0
    if phase not in _BEFORE:
        return 0.0
    f = min(max(fraction, 0.0), 1.0)
    return min(1.0, (_BEFORE[phase] + _WEIGHT[phase] * f) / _total)


class BuildBar:
    """A tqdm bar over the overall fraction (in percent), with the phase as postfix."""

    @staticmethod
    def wanted(progress):
        if progress is None:
            return sys.stderr is not None and sys.stderr.isatty()
        return bool(progress)

    @classmethod
    def create(cls, progress):
        """A bar when ``progress`` asks for one (None: when stderr is a terminal) and tqdm is
        installed (Debian python3-tqdm); None otherwise."""
        if not cls.wanted(progress):
            return None
        try:
            from tqdm import tqdm
        except ImportError:
            return None
        return cls(tqdm)

    def __init__(self, tqdm):
        self._bar = tqdm(total=100.0, unit="%", file=sys.stderr, dynamic_ncols=True, leave=True,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]"
                                    "{postfix}")
        self._described = False

    def update(self, progress):
        if not self._described and progress.basis_id:
            self._bar.set_description_str("build %s%s" % (
                progress.basis_id, " (joined)" if progress.joined else ""), refresh=False)
            self._described = True
        self._bar.set_postfix_str(progress.phase, refresh=False)
        target = 100.0 * progress.overall
        if target > self._bar.n:
            self._bar.update(target - self._bar.n)
        else:
            self._bar.refresh()

    def close(self):
        self._bar.close()
