"""Block statistics of the varying-coefficient design, summed over any weighting of the blocks.

A section's fit needs the sufficient statistics (X^T X, X^T y, y^T y) of its design
(:mod:`vivbench.models.varying_design`) summed over different sets of its time blocks:
the cross-validation folds, the events (leave-one-event-out), the bootstrap's block
multiplicities. :class:`BlockStats` holds them once and gives every such sum,
``sums(weights)`` with ``weights`` (R, n_blocks).

With one wind input (``wind_input`` "mean" or "section") they are held as moments: an
entry of a block's X^T X is sum A^(i + i') z^(j + j') B_a(U) B_a'(U) over its samples,
so the samples of a block in one knot interval (a group) need only the moments
sum A^p z^q B_a B_a' (p <= 6, q <= 2 J; a, a' over the interval's DEGREE + 1 B-splines)
and sum A^p z^q y B_a: a few hundred numbers per group instead of the blocks' p x p
Grams, and one small product over its samples instead of their Q x Q one. A sum over
blocks is a weighted sum of the groups' moments, spread into the p x p layout once
per knot interval. With the tied sum of every section's wind (``wind_input="sum"``,
:func:`tied_statistics`) a row is A^i c_(j, m), c_(j, m) = sum_s w_s z_s^j B_m(U_s), and each
block keeps the moments sum A^p c c^T (p <= 6) and sum A^i y c. Otherwise (several wind
inputs) the blocks' Grams are kept as :func:`~vivbench.models.varying_design.block_stats` gives them.
"""

from __future__ import annotations

import numpy as np

from vivbench.library.splines import DEGREE, first_index, uniform_cubic_local_t
from vivbench.models.varying_design import block_stats, group_chunks, key_groups

__all__ = ["BlockStats", "block_statistics", "one_hot", "tied_statistics"]

#: Powers of the scaled amplitude in the moments of X^T X: orders i + i' of 0..3 each.
_A_POWERS = 7

#: The pairs a <= a' of an interval's B-splines (B_a B_a' is symmetric), and each (a, a')'s pair.
_PAIRS = np.array([(a, b) for a in range(DEGREE + 1) for b in range(a, DEGREE + 1)])
_PAIR_OF = np.zeros((DEGREE + 1, DEGREE + 1), dtype=np.intp)
_PAIR_OF[_PAIRS[:, 0], _PAIRS[:, 1]] = _PAIR_OF[_PAIRS[:, 1], _PAIRS[:, 0]] = np.arange(len(_PAIRS))


def one_hot(labels: np.ndarray, n: int) -> np.ndarray:
    """Weights (n, len(labels)) that sum the blocks by label (0..n-1): ``sums(one_hot(fold_of_block, K))``."""
    labels = np.asarray(labels)
    return (labels[None, :] == np.arange(n)[:, None]).astype(float)


def _powers(x: np.ndarray, top: int) -> np.ndarray:
    """x^0 .. x^top by repeated products, shape (top + 1, n)."""
    out = np.empty((top + 1, x.size))
    out[0] = 1.0
    for q in range(1, top + 1):  # a few powers
        np.multiply(out[q - 1], x, out=out[q])
    return out


class BlockStats:
    """Per-block sufficient statistics of one equation's design, summed over weighted blocks on demand.

    Built by :func:`block_statistics`. ``n_blocks`` blocks, ``p`` columns; ``count`` (n_blocks,)
    the samples per block.
    """

    def __init__(self, *, n_blocks: int, p: int, yy: np.ndarray, count: np.ndarray, dense=None, moments=None,
                 tied=None):
        self.n_blocks, self.p = int(n_blocks), int(p)
        self.yy, self.count = np.asarray(yy, dtype=float), np.asarray(count)
        self._dense, self._moments, self._tied = dense, moments, tied

    def sums(self, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The statistics of weighted sums of the blocks.

        Parameters
        ----------
        weights : ndarray, shape (R, n_blocks)

        Returns
        -------
        G : ndarray, shape (R, p, p); b : ndarray, shape (R, p); yy : ndarray, shape (R,)
        """
        W = np.asarray(weights, dtype=float).reshape(-1, self.n_blocks)
        yy = W @ self.yy
        if self._dense is not None:
            G, b = self._dense
            return (W @ G.reshape(self.n_blocks, -1)).reshape(-1, self.p, self.p), W @ b, yy
        if self._tied is not None:
            mom, by = self._tied  # (n_blocks, 7, K, K), (n_blocks, 4, K)
            K = mom.shape[-1]
            m = (W @ mom.reshape(self.n_blocks, -1)).reshape(-1, _A_POWERS, K, K)
            i = np.arange(4)
            G = m[:, i[:, None] + i[None, :]].transpose(0, 1, 3, 2, 4)  # entry (i, (j, m)), (i', (j', m'))
            return G.reshape(-1, self.p, self.p), W @ by.reshape(self.n_blocks, -1), yy
        return (*self._spread(W), yy)

    def by(self, labels: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The statistics summed over the blocks of each label 0..n-1 (e.g. each fold's or event's),
        shapes as :meth:`sums`."""
        return self.sums(one_hot(labels, n))

    def total(self) -> tuple[np.ndarray, np.ndarray, float]:
        """The statistics of every block: G (p, p), b (p,), yy."""
        G, b, yy = self.sums(np.ones((1, self.n_blocks)))
        return G[0], b[0], float(yy[0])

    def _spread(self, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Weighted sums of the groups' moments, spread into the (i, j, m) layout, knot interval by interval."""
        mom, gblock, gint, n_yaw, M = self._moments
        IJ, nb4, n_q = 4 * (n_yaw + 1), DEGREE + 1, 2 * n_yaw + 1
        R = W.shape[0]
        # entry ((i, j, a), (i', j', a')) of a group's Gram is its moment (i + i', j + j', a, a')
        ii, jj = np.divmod(np.arange(IJ), n_yaw + 1)
        pq = (ii[:, None] + ii[None, :]) * n_q + jj[:, None] + jj[None, :]  # (IJ, IJ)
        n_pairs = len(_PAIRS)
        G = np.zeros((R, IJ, M, IJ, M))
        b = np.zeros((R, IJ, M))
        Wg = W[:, gblock]  # (R, groups)
        for f in range(M - DEGREE):  # the knot intervals, not the samples or groups
            g = np.flatnonzero(gint == f)
            if not g.size:
                continue
            m = (Wg[:, g] @ mom[g].reshape(g.size, -1)).reshape(R, -1, n_pairs + nb4)
            G[:, :, f:f + nb4, :, f:f + nb4] += m[:, pq[:, None, :, None], _PAIR_OF[None, :, None, :]]
            b[:, :, f:f + nb4] += m[:, ii * n_q + jj, n_pairs:]
        p = IJ * M
        return G.reshape(R, p, p), b.reshape(R, p)


def block_statistics(U: np.ndarray, A: np.ndarray, y: np.ndarray, block: np.ndarray, n_blocks: int,
                     knots: np.ndarray, a_ref: float, z: np.ndarray | None = None, n_yaw: int = 0,
                     weight: np.ndarray | None = None, chunk: int = 16_384) -> BlockStats:
    """The statistics of :func:`~vivbench.models.varying_design.block_stats` as a :class:`BlockStats`.

    Parameters
    ----------
    U : ndarray, shape (n,) or (n, n_in), m/s (finite)
    A : ndarray, shape (n,), m; y : ndarray, shape (n,) (the standardised target)
    block : ndarray of int, shape (n,), 0..n_blocks-1
    knots : ndarray, shape (M + DEGREE + 1,), uniform (:func:`vivbench.library.splines.uniform_knots`)
    a_ref : float, m; z : ndarray like U or None (the scaled yaw covariate); n_yaw : int
    weight : ndarray, shape (n,), optional (weighted least squares)
    chunk : int
        Samples handled at once (memory).
    """
    U2 = np.asarray(U, dtype=float).reshape(np.shape(U)[0], -1)
    n, n_in = U2.shape
    M = knots.size - DEGREE - 1
    if n_in > 1:
        G, b, yy, cnt = block_stats(U, A, y, block, n_blocks, knots, a_ref, z, n_yaw, weight, chunk)
        return BlockStats(n_blocks=n_blocks, p=G.shape[-1], yy=yy, count=cnt, dense=(G, b))
    u = U2[:, 0]
    block = np.asarray(block, dtype=np.int64)
    zz = None if z is None else np.asarray(z, dtype=float).reshape(n)
    w = None if weight is None else np.asarray(weight, dtype=float)
    yw2 = y**2 if w is None else y**2 * w
    yy = np.bincount(block, weights=yw2, minlength=n_blocks)
    cnt = np.bincount(block, minlength=n_blocks)
    n_int = M - DEGREE
    order, ks, starts, ends = key_groups(block * n_int + first_index(u, knots))
    n_pq, nb4, n_pairs = _A_POWERS * (2 * n_yaw + 1), DEGREE + 1, len(_PAIRS)
    # per group: sum A^p z^q B_a B_a' (a <= a'), then sum A^p z^q y B_a
    mom = np.empty((starts.size, n_pq, n_pairs + nb4))
    a = np.asarray(A, dtype=float) / a_ref
    for g0, g1 in group_chunks(starts, chunk):  # chunks of whole groups
        sel = order[starts[g0]:ends[g1 - 1]]
        _first, B = uniform_cubic_local_t(u[sel], knots)  # (4, m)
        P = _powers(a[sel], _A_POWERS - 1)
        if n_yaw:
            P = (P[:, None, :] * _powers(zz[sel], 2 * n_yaw)[None, :, :]).reshape(n_pq, sel.size)
        F = np.empty((n_pairs + nb4, sel.size))
        np.multiply(B[_PAIRS[:, 0]], B[_PAIRS[:, 1]], out=F[:n_pairs])
        np.multiply(B, y[sel], out=F[n_pairs:])
        if w is not None:
            F *= w[sel]
        off = starts[g0]
        for g in range(g0, g1):  # one small product per group (a few per block), not per sample
            r = slice(starts[g] - off, ends[g] - off)
            mom[g] = P[:, r] @ F[:, r].T
    gblock, gint = np.divmod(ks[starts], n_int)
    return BlockStats(n_blocks=n_blocks, p=4 * (n_yaw + 1) * M, yy=yy, count=cnt,
                      moments=(mom, gblock, gint, n_yaw, M))


def tied_statistics(U: np.ndarray, A: np.ndarray, y: np.ndarray, block: np.ndarray, n_blocks: int,
                    knots: np.ndarray, a_ref: float, weights: np.ndarray, z: np.ndarray | None = None,
                    n_yaw: int = 0, weight: np.ndarray | None = None, chunk: int = 65_536) -> BlockStats:
    """The block statistics of the tied design (one curve for every section's wind) as a :class:`BlockStats`.

    The columns, ordered (i, j, m), are (A / a_ref)^i sum_s w_s z_s^j B_m(U_s): X T, with X the design
    of :func:`~vivbench.models.varying_design.block_stats` with every section's wind as an input and T the
    tying of :func:`~vivbench.models.varying_design.untie`, but without the untied Grams, whose size grows
    with the square of the number of sections.

    Parameters
    ----------
    U : ndarray, shape (n, S), m/s (finite): every section's wind
    A : ndarray, shape (n,), m; y : ndarray, shape (n,) (the standardised target)
    block : ndarray of int, shape (n,), 0..n_blocks-1
    knots : ndarray, shape (M + DEGREE + 1,), uniform (:func:`vivbench.library.splines.uniform_knots`)
    a_ref : float, m
    weights : ndarray, shape (S,); the sections' weights w_s
    z : ndarray, shape (n, S), or None (the scaled yaw covariate of every section); n_yaw : int
    weight : ndarray, shape (n,), optional (weighted least squares)
    chunk : int
        Samples handled at once (memory: chunk (J + 1) M rows of the tied curves' values).
    """
    U2 = np.asarray(U, dtype=float).reshape(np.shape(U)[0], -1)
    n, S = U2.shape
    M = knots.size - DEGREE - 1
    J1 = n_yaw + 1
    K = J1 * M
    w_s = np.asarray(weights, dtype=float).reshape(S)
    z2 = None if z is None else np.asarray(z, dtype=float).reshape(n, S)
    block = np.asarray(block, dtype=np.int64)
    yw = y if weight is None else y * weight
    yy = np.bincount(block, weights=y * yw, minlength=n_blocks)
    cnt = np.bincount(block, minlength=n_blocks)
    first = np.stack([first_index(U2[:, s_], knots) for s_ in range(S)])  # (S, n)
    lo = first.min(axis=0)
    # Groups: the samples of a block with the same lowest first B-spline. A row's non-zero tied columns lie
    # in lo .. max_s first_s + DEGREE of each yaw power's M: a window of a few B-splines where the sections'
    # winds are close, so each group's product is over its window, not over every M.
    order, ks, starts, ends = key_groups(block * M + lo)
    mom = np.zeros((n_blocks, _A_POWERS, K, K))
    by = np.zeros((n_blocks, 4, K))
    a = np.asarray(A, dtype=float) / a_ref
    for g0, g1 in group_chunks(starts, chunk):  # chunks of whole groups
        sel = order[starts[g0]:ends[g1 - 1]]
        rows = np.arange(sel.size)
        off = first[:, sel] - lo[sel]  # (S, samples): each section's B-splines within the window
        span = off.max(axis=0) + DEGREE + 1  # each sample's window
        Wc = int(span.max())
        # the tied curves' basis values c_(j, lo + d) at each sample, summed over the sections' B-splines
        idx = np.empty((S, J1, DEGREE + 1, sel.size), dtype=np.intp)
        val = np.empty(idx.shape)
        shift = (np.arange(J1)[:, None, None] * Wc + np.arange(DEGREE + 1)[:, None])  # (J1, 4, 1)
        for s_ in range(S):  # a few sections
            _f, B = uniform_cubic_local_t(U2[sel, s_], knots, first[s_, sel])
            np.add(shift, rows * (J1 * Wc) + off[s_], out=idx[s_])
            if z2 is None:
                np.multiply(B, w_s[s_], out=val[s_, 0])
            else:
                np.multiply((w_s[s_] * B)[None], _powers(z2[sel, s_], n_yaw)[:, None, :], out=val[s_])
        C = np.bincount(idx.ravel(), weights=val.ravel(), minlength=sel.size * J1 * Wc).reshape(sel.size, J1, Wc)
        if weight is not None:
            Cw = C * weight[sel, None, None]
        P = _powers(a[sel], _A_POWERS - 1)  # (7, samples)
        PT = P.T
        base = starts[g0]
        for g in range(g0, g1):  # one product per group (a few per block), not per sample
            r = slice(starts[g] - base, ends[g] - base)
            W = int(span[r].max())
            Cg = C[r, :, :W].reshape(-1, J1 * W)
            Cgw = Cg if weight is None else Cw[r, :, :W].reshape(-1, J1 * W)
            PC = (PT[r, :, None] * Cgw[:, None, :]).reshape(Cg.shape[0], -1)  # (samples, 7 J1 W), contiguous
            blk, l0 = divmod(int(ks[starts[g]]), M)
            Rg = (Cg.T @ PC).reshape(J1, W, _A_POWERS, J1, W)
            bg = ((P[:4, r] * yw[sel[r]]) @ Cg).reshape(4, J1, W)
            for j in range(J1):  # the window's columns of each yaw power: contiguous
                cj = slice(j * M + l0, j * M + l0 + W)
                by[blk, :, cj] += bg[:, j]
                for j2 in range(J1):
                    mom[blk, :, cj, j2 * M + l0:j2 * M + l0 + W] += Rg[j, :, :, j2].transpose(1, 0, 2)
    return BlockStats(n_blocks=n_blocks, p=4 * K, yy=yy, count=cnt, tied=(mom, by))
