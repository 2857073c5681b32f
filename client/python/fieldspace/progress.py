"""Build progress: a tqdm bar over the server's estimate of the whole build done.

The server reports the current phase, the fraction done of that phase and an overall fraction
(`BuildBasisProgress.overall_fraction`: the phases weighted by their typical share of a build's
time, server/served_basis.cc); the bar and its ETA follow the overall fraction.
"""

import sys


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
