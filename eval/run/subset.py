"""Which cases a run takes (``dataset.sample=K``, :func:`sample_cases`: a seeded uniform
sample, in the dataset's order) and which of them the full-resolution baselines run on
(``dataset.baseline_cases``). Floor 0 of eval/ (tests/test_layering.py); docs/implementation.md.

- ``per_pose`` (DeFAUST's default): one case per target pose, from different subjects.
  With the target poses present sorted ``p_0 < p_1 < ...`` and the subjects present
  sorted ``s_0 < s_1 < ...`` (``n`` of them), pose ``p_j`` is taken from subject
  ``s_(j mod n)`` (for DeFAUST's poses 1..4 and subjects 0..9: pose ``p`` from subject
  ``(p - 1) mod 10``, i.e. s00_p01 .. s03_p04); when that subject has no such case (e.g.
  after ``dataset.limit``), the next subject in that cyclic order that has it.
- an integer ``N``: the first ``N`` cases (the dataset's order); ``0``: none.
- ``all`` or null: every case."""
from __future__ import annotations

import hashlib

from sshade.errors import SShaDeError

__all__ = ["baseline_selection", "check_baseline_cases", "check_method_cases", "method_selections", "PER_POSE",
           "check_sample", "sample_cases", "take_sample"]

PER_POSE = "per_pose"


def check_baseline_cases(v):
    """``dataset.baseline_cases`` checked: None (= all), ``"all"``, ``"per_pose"`` or an
    int >= 0 (bools refused; numeric strings accepted). Raises SShaDeError naming the key.

    >>> check_baseline_cases("per_pose"), check_baseline_cases("3"), check_baseline_cases(None)
    ('per_pose', 3, None)
    """
    if v is None or isinstance(v, str) and v.strip().lower() in ("all", "null", "none"):
        return None
    if isinstance(v, str) and v.strip().lower() == PER_POSE:
        return PER_POSE
    if not isinstance(v, bool):
        try:
            n = int(str(v).strip())
            if n >= 0 and str(n) == str(v).strip():
                return n
        except ValueError:
            pass
    raise SShaDeError(f"dataset.baseline_cases must be all, per_pose or an integer >= 0 (the first N cases), "
                      f"got {v!r}")


def _per_pose(cases) -> set[int]:
    poses = sorted({c.pose for c in cases if c.pose is not None})
    subjects = sorted({c.subject for c in cases if c.subject is not None})
    where = {(c.subject, c.pose): i for i, c in reversed(list(enumerate(cases)))}  # the first case of a pair
    out = set()
    for j, p in enumerate(poses):
        for k in range(len(subjects)):
            i = where.get((subjects[(j + k) % len(subjects)], p))
            if i is not None:
                out.add(i)
                break
    return out


def baseline_selection(cases, spec) -> tuple[set[int] | None, str]:
    """``(indices, rule)``: the indices of ``cases`` (objects with ``subject`` and
    ``pose``) the baselines run on (None: every case) and the rule in words, for the table.

    >>> from types import SimpleNamespace as C
    >>> cs = [C(subject=s, pose=p) for s in range(3) for p in (1, 2)]
    >>> baseline_selection(cs, "per_pose")
    ({0, 3}, 'per_pose: one case per target pose, pose p_j from subject s_(j mod 3) (2 cases)')
    >>> baseline_selection(cs, 1)[1], baseline_selection(cs, "all")
    ('the first 1 case(s)', (None, 'all cases'))

    Raises SShaDeError for a bad ``spec`` (:func:`check_baseline_cases`).
    """
    spec = check_baseline_cases(spec)
    if spec is None:
        return None, "all cases"
    if spec == PER_POSE:
        sel = _per_pose(cases)
        n_subj = len({c.subject for c in cases if c.subject is not None})
        return sel, (f"per_pose: one case per target pose, pose p_j from subject s_(j mod {n_subj}) "
                     f"({len(sel)} cases)")
    return set(range(min(spec, len(cases)))), f"the first {spec} case(s)"


def check_method_cases(spec, names=None) -> dict:
    """``method_cases`` checked: None / empty = {}; else a mapping of method names (among
    ``names`` when given) to :func:`check_baseline_cases` rules. Returns a plain dict.

    >>> check_method_cases({"Implicit-ARAP": "per_pose"}, ["SShaDe", "Implicit-ARAP"])
    {'Implicit-ARAP': 'per_pose'}

    Raises SShaDeError for a value that is not a mapping, a name not among ``names``, or
    a bad rule.
    """
    if spec is None:
        return {}
    try:
        items = dict(spec.items())
    except AttributeError:
        raise SShaDeError(f"method_cases must be a mapping of method names to case rules (all, per_pose or an "
                          f"integer), e.g. {{Implicit-ARAP: per_pose}}; got {spec!r}") from None
    out = {}
    for k, v in items.items():
        if names is not None and str(k) not in names:
            raise SShaDeError(f"method_cases names {k!r}, which is not among the methods run ({list(names)})")
        try:
            out[str(k)] = check_baseline_cases(v)
        except SShaDeError as e:
            raise SShaDeError(f"method_cases.{k}: {e}") from None
    return out


def method_selections(cases, spec, names) -> dict:
    """``{name: (indices or None, rule in words)}`` for each method ``spec``
    (``method_cases``, :func:`check_method_cases`) gives its own rule; see
    :func:`baseline_selection`.

    >>> from types import SimpleNamespace as C
    >>> cs = [C(subject=s, pose=p) for s in range(3) for p in (1, 2)]
    >>> method_selections(cs, {"Implicit-ARAP": 1}, ["SShaDe", "Implicit-ARAP"])
    {'Implicit-ARAP': ({0}, 'the first 1 case(s)')}

    Raises SShaDeError as :func:`check_method_cases`.
    """
    return {k: baseline_selection(cases, v) for k, v in check_method_cases(spec, names).items()}


def check_sample(k, seed) -> tuple[int | None, int]:
    """``(dataset.sample, dataset.sample_seed)`` checked: None or an int >= 1 (bools
    refused; numeric strings accepted), and an int >= 0. Raises SShaDeError naming the key.

    >>> check_sample("40", 0), check_sample(None, 3)
    ((40, 0), (None, 3))
    """
    def whole(v, lo: int, key: str, what: str) -> int:
        if not isinstance(v, bool):
            try:
                n = int(str(v).strip())
                if n >= lo and str(n) == str(v).strip():
                    return n
            except ValueError:
                pass
        raise SShaDeError(f"dataset.{key} must be {what}, got {v!r}")

    n = None if k is None else whole(k, 1, "sample", "null (every case) or an integer >= 1 (that many cases)")
    return n, whole(0 if seed is None else seed, 0, "sample_seed", "an integer >= 0")


def _rank(seed: int, case) -> bytes:
    return hashlib.sha256(f"{seed}:{case.subject}:{case.pose}".encode()).digest()


def sample_cases(cases, k, seed=0) -> tuple[list[int] | None, str]:
    """``(indices, rule)``: the indices of a seeded sample of ``k`` of ``cases`` (objects
    with ``subject`` and ``pose``, unique pairs) in the dataset's order (None: every
    case, ``k`` None or at least the number of cases) and the rule in words, for the table.

    The sample is the ``k`` cases of least SHA-256 of ``"{seed}:{subject}:{pose}"``
    (bottom-k sampling: uniform without replacement). A case's key depends only on its
    own ``(subject, pose)`` and the seed, never on the other cases, the dataset's order,
    the platform or NumPy's version; with one seed a sample of ``k`` is part of the
    sample of ``k + 1``.

    >>> from types import SimpleNamespace as C
    >>> cs = [C(subject=s, pose=p) for s in range(10) for p in (1, 2, 3, 4)]
    >>> idx, rule = sample_cases(cs, 3, seed=0)
    >>> len(idx), idx == sorted(idx), rule
    (3, True, 'a seeded sample of 3 of 40 cases: dataset.sample=3, sample_seed=0')
    >>> set(idx) <= set(sample_cases(cs, 4, seed=0)[0]), sample_cases(cs, 40)
    (True, (None, 'all 40 cases: dataset.sample=40'))

    Raises SShaDeError for a bad ``k`` or ``seed`` (:func:`check_sample`) or a repeated
    ``(subject, pose)``.
    """
    k, seed = check_sample(k, seed)
    if k is None:
        return None, f"all {len(cases)} cases"
    keys = [(c.subject, c.pose) for c in cases]
    if len(set(keys)) != len(keys):
        raise SShaDeError("dataset.sample needs cases with distinct (subject, pose); this dataset repeats one")
    if k >= len(cases):
        return None, f"all {len(cases)} cases: dataset.sample={k}"
    chosen = sorted(sorted(range(len(cases)), key=lambda i: _rank(seed, cases[i]))[:k])
    return chosen, f"a seeded sample of {k} of {len(cases)} cases: dataset.sample={k}, sample_seed={seed}"


def take_sample(cases, k, seed=0) -> tuple[list, str]:
    """``(kept, rule)``: the cases :func:`sample_cases` draws (all of them when it draws
    every case), in the dataset's order, and its rule in words. Raises as there."""
    idx, rule = sample_cases(cases, k, seed)
    return (list(cases) if idx is None else [cases[i] for i in idx]), rule
