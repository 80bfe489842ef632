"""The sequence :func:`defaust.load` returns (:class:`CaseSequence`): a DeFAUST build's
cases, each read from its files when first asked for (by position, by name or by
iteration), then kept. Indexed like a list (``len``, iteration in (subject, pose) order,
negative positions, slices) and by case name (``"s00_p01"`` or the manifest's
``"subject_00/pose_01"``); a file shared by several cases is read and checked once;
thread-safe; a pickled copy holds no array. Usage: docs/defaust.md §6, "A lazy, indexed
sequence".

Example::

    cases = defaust.load("data/defaust", resolution="low")   # reads the manifest only
    c = cases["s00_p01"]; c is cases[0], len(cases)           # -> (True, 40)
"""
from __future__ import annotations

import operator
import threading
from collections.abc import Callable, Hashable, Sequence

__all__ = ["CaseSequence", "Once", "case_name", "item_key"]


def case_name(subject: int, pose: int) -> str:
    """The reader's name of case (subject, pose).

    Examples
    --------
    >>> case_name(0, 3)
    's00_p03'
    """
    return f"s{subject:02d}_p{pose:02d}"


def item_key(subject: int, pose: int) -> str:
    """The manifest's item key of case (subject, pose).

    Examples
    --------
    >>> item_key(0, 3)
    'subject_00/pose_03'
    """
    return f"subject_{subject:02d}/pose_{pose:02d}"


class Once:
    """Values made once per key, thread-safe: :meth:`get` makes a missing value under the
    key's own lock (other keys are made in parallel) and keeps it; a ``make`` that raises
    keeps nothing (the next :meth:`get` tries again). Pickles empty.

    Examples
    --------
    >>> o = Once(); o.get("a", lambda: 1), o.get("a", lambda: 2), "a" in o
    (1, 1, True)
    """

    def __init__(self):
        self._values: dict = {}
        self._locks: dict = {}
        self._lock = threading.Lock()

    def get(self, key: Hashable, make: Callable):
        try:
            return self._values[key]
        except KeyError:
            pass
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            if key not in self._values:
                self._values[key] = make()
            return self._values[key]

    def __contains__(self, key) -> bool:
        return key in self._values

    def __len__(self) -> int:
        return len(self._values)

    def __getstate__(self):
        return {}

    def __setstate__(self, state):
        self.__init__()


class CaseSequence(Sequence):
    """The cases of a DeFAUST build, read on first access (:func:`defaust.load` makes it).

    Indexing
    --------
    ``cases[i]`` : int (numpy ints too; negative from the end) -> :class:`defaust.dataset.Case`.
    ``cases["s00_p01"]`` or ``cases["subject_00/pose_01"]`` -> the case of that name.
    ``cases[a:b:c]`` -> a CaseSequence of those cases (sharing what was read).
    ``len(cases)``, ``iter(cases)`` (subject, pose) order, ``name in cases``,
    :meth:`index` (a name's position) and :attr:`names` read no file.

    Attributes
    ----------
    names : tuple of str, the cases' names in order. root : Path of the build (a folder
    or an archive). resolution : ``"high"`` or ``"low"``. source : the build's source
    (``"anny"``, ``"faust"``, ``"synthetic"``).

    Raises
    ------
    IndexError (a position out of range), KeyError (a name not in the sequence; the
    message says whether the build has it outside this selection), TypeError (another
    key); a case's files raise as :func:`defaust.load` says (SShaDeError, one line naming
    the file) when that case is first asked for.
    """

    def __init__(self, reader, keys: Sequence[tuple[int, int]]):
        self._reader = reader
        self._keys = tuple(keys)
        self.names = tuple(case_name(s, p) for s, p in self._keys)
        self._pos = {n: i for i, n in enumerate(self.names)}
        self._pos.update({item_key(s, p): i for i, (s, p) in enumerate(self._keys)})

    @property
    def root(self):
        return self._reader.root

    @property
    def resolution(self) -> str:
        return self._reader.resolution

    @property
    def source(self) -> str:
        return self._reader.source

    def __len__(self) -> int:
        return len(self._keys)

    def __getitem__(self, key):
        if isinstance(key, slice):
            return CaseSequence(self._reader, self._keys[key])
        return self._reader.case(*self._keys[self._position(key)])

    def __iter__(self):
        for s, p in self._keys:
            yield self._reader.case(s, p)

    def __contains__(self, x) -> bool:
        name = x if isinstance(x, str) else getattr(x, "name", None)
        return isinstance(name, str) and name in self._pos and (
            isinstance(x, str) or getattr(x, "resolution", None) == self.resolution)

    def index(self, x, start: int = 0, stop: int | None = None) -> int:
        """Position of the case named ``x`` (or of the case ``x``), reading no file.

        Raises
        ------
        ValueError if it is not in the sequence (between ``start`` and ``stop``)."""
        name = x if isinstance(x, str) else getattr(x, "name", None)
        i = self._pos.get(name) if isinstance(name, str) else None
        if i is None or not (range(len(self))[start:stop].count(i)):
            raise ValueError(f"{x!r} is not in this sequence of {len(self)} DeFAUST case(s)")
        return i

    def count(self, x) -> int:
        """1 if the case named ``x`` is in the sequence, else 0 (reads no file)."""
        return int(x in self)

    def _position(self, key) -> int:
        """The position of an int or a name, or the error of the class docstring."""
        if isinstance(key, str):
            i = self._pos.get(key)
            if i is None:
                raise KeyError(self._missing(key))
            return i
        if isinstance(key, bool):
            raise TypeError(self._bad_key(key))
        try:
            i = operator.index(key)
        except TypeError:
            raise TypeError(self._bad_key(key)) from None
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"case index {i} out of range: this sequence has {n} case(s) (0 to {n - 1}, or -{n} "
                             "to -1 from the end)" if n else f"case index {i} out of range: this sequence is empty")
        return i % n

    def _bad_key(self, key) -> str:
        return (f"DeFAUST cases are indexed by position (int), name ('s00_p01' or 'subject_00/pose_01') or slice, "
                f"got {type(key).__name__} {key!r}")

    def _missing(self, key: str) -> str:
        """The KeyError message for the name ``key``."""
        where = f"{self.root} (resolution {self.resolution!r})"
        if key in self._reader.all_names:
            return (f"case {key!r} is in {where} but not in this selection of {len(self)} case(s) "
                    "(load's subjects/limit, or a slice)")
        have = (", ".join(self.names) if len(self) <= 6 else
                f"{', '.join(self.names[:3])}, ..., {', '.join(self.names[-2:])}")
        return (f"no case {key!r} in {where}; cases are named sXX_pYY (or by the manifest's subject_XX/pose_YY), "
                f"these {len(self)}: {have}")

    def __repr__(self) -> str:
        read = sum(k in self._reader.cases for k in self._keys)
        return (f"<CaseSequence of {len(self)} DeFAUST case(s) of {self.root}, resolution={self.resolution!r}, "
                f"{read} read>")
