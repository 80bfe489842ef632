"""eval/run/subset.py: the run's seeded sample of cases (``dataset.sample``); the
baselines' case rules are tested with the store (tests/test_store.py)."""
from __future__ import annotations

import random
from types import SimpleNamespace as C

import pytest

from eval.run.subset import check_sample, sample_cases, take_sample
from sshade.errors import SShaDeError

CASES = [C(subject=s, pose=p) for s in range(10) for p in (1, 2, 3, 4)]


def _pairs(cases, idx) -> set:
    return {(cases[i].subject, cases[i].pose) for i in idx}


def test_a_sample_is_the_same_cases_whatever_the_datasets_order():
    shuffled = CASES[:]
    random.Random(1).shuffle(shuffled)
    for seed in range(5):
        a, _ = sample_cases(CASES, 7, seed)
        b, _ = sample_cases(shuffled, 7, seed)
        assert _pairs(CASES, a) == _pairs(shuffled, b)
        assert a == sorted(a) and b == sorted(b)  # kept in each dataset's own order


def test_a_sample_of_k_is_part_of_the_sample_of_k_plus_one():
    for seed in range(3):
        prev: set = set()
        for k in range(1, len(CASES)):
            cur = set(sample_cases(CASES, k, seed)[0])
            assert prev <= cur and len(cur) == k
            prev = cur


def test_every_case_is_drawn_about_k_over_n_of_the_seeds():
    """Uniform without replacement: over 2000 seeds each of 10 cases is drawn with k=3 on
    about 600 of them (binomial sd 20.5; the bound is 5 sd)."""
    cases = CASES[:10]
    counts = [0] * 10
    for seed in range(2000):
        for i in sample_cases(cases, 3, seed)[0]:
            counts[i] += 1
    assert all(abs(c - 600) < 103 for c in counts), counts


def test_other_seeds_draw_other_samples_and_k_at_least_n_keeps_every_case():
    assert len({tuple(sample_cases(CASES, 5, s)[0]) for s in range(20)}) > 15
    assert sample_cases(CASES, 40) == (None, "all 40 cases: dataset.sample=40")
    assert sample_cases(CASES, None)[0] is None
    kept, rule = take_sample(CASES, 2, 0)
    assert len(kept) == 2 and rule == "a seeded sample of 2 of 40 cases: dataset.sample=2, sample_seed=0"


@pytest.mark.parametrize("k,seed,word", [(0, 0, "dataset.sample "), (True, 0, "dataset.sample "),
                                         ("x", 0, "dataset.sample "), (2.5, 0, "dataset.sample "),
                                         (2, -1, "dataset.sample_seed"), (2, "a", "dataset.sample_seed")])
def test_a_bad_sample_or_seed_is_refused_naming_its_key(k, seed, word):
    with pytest.raises(SShaDeError, match=word):
        check_sample(k, seed)


def test_a_dataset_that_repeats_a_subject_and_pose_cannot_be_sampled():
    with pytest.raises(SShaDeError, match="distinct"):
        sample_cases([C(subject=0, pose=1), C(subject=0, pose=1), C(subject=1, pose=1)], 1)
