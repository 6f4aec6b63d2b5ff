"""Ragged rows in flat arrays, as the batched reactive step keeps them: each pedestrian's candidates one after
another, each crowd's pedestrians in a row. Runs of indices, the True columns of each row first, and row sums that
round as numpy rounds the dense rows (so that a batched sum equals the sum of one pedestrian scored alone, to the
last bit).
"""

from __future__ import annotations

import numpy as np


def leading(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(columns (N, K), real (N, K) bool): each row's True columns of ``mask`` (N, A) first, ascending, the rows cut
    to the most True columns of any, K (padded with False columns, ``real`` False)."""
    width = int(mask.sum(axis=1).max(initial=0))
    columns = np.argsort(~mask, axis=1, kind="stable")[:, :width]
    return columns, np.take_along_axis(mask, columns, axis=1)


def distinct(values: np.ndarray) -> np.ndarray:
    """(J, K) bool: the first of each run of equal values in the sorted rows ``values`` (J, K) (``np.unique``'s)."""
    return np.concatenate([np.ones((len(values), 1), bool), values[:, 1:] != values[:, :-1]], axis=1)


def spans(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(sum of counts,) the runs ``starts[i], ..., starts[i] + counts[i] - 1`` (K,) each, one after another."""
    return np.repeat(starts - (np.cumsum(counts) - counts), counts) + np.arange(counts.sum())


def exact_row_sums(row: np.ndarray, column: np.ndarray, value: np.ndarray, width: np.ndarray,
                   n_rows: int) -> np.ndarray:
    """(n_rows,) the row sums of a sparse matrix, each row as numpy sums it dense (zeros and the values at
    ``column`` of row ``row``, (E,) each, a row ``width[row]`` (n_rows,) long): a row with at most two non-zero
    values is their sum in any order; one with more is summed dense, so that the rounding is numpy's."""
    keep = value != 0
    row, column, value = row[keep], column[keep], value[keep]
    total = np.bincount(row, value, minlength=n_rows)
    many = np.flatnonzero(np.bincount(row, minlength=n_rows) > 2)
    for size in np.unique(width[many]):
        which = many[width[many] == size]
        mine = np.isin(row, which)
        dense = np.zeros((len(which), size))
        dense[np.searchsorted(which, row[mine]), column[mine]] = value[mine]
        total[which] = dense.sum(axis=1)
    return total
