"""An index of keyframes by their ORB descriptors: which keyframes share descriptors with a query, without matching
the query against every keyframe.

ORB's descriptors are 256-bit strings compared by Hamming distance. :class:`OrbIndex` is a multi-table
locality-sensitive hash (Indyk and Motwani's bit sampling, as FLANN's LSH index): each of ``n_tables`` tables keys a
descriptor by ``bits`` of its 256 bits, at positions drawn once from a seeded generator, and keeps the rows of the
descriptors under each key in a dict. Two descriptors at Hamming distance ``d`` share a table's key with probability
``(1 − d/256)^bits``: at the default 16 bits and 16 tables, a descriptor at distance 30 (a typical ORB match) shares
at least one key with probability 0.90, at 48 with 0.44, one at 128 (unrelated) with 16 · 2⁻¹⁶.

A query looks up its descriptors' keys, keeps the indexed descriptors it meets within ``max_distance`` (the exact
Hamming distance: the hash only proposes) and gives each keyframe one **vote** per query descriptor that met at
least one of its descriptors. ORB's bits are far from independent, so unrelated descriptors come closer than random
strings would: within the default 48 bits, views of different walls of the synthetic room share at most 13 votes
where views of the same wall share 56 or more (within 64 bits: 62 and 74). The votes rank the keyframes worth the
exact, pairwise ratio-test matching (:class:`~dmtrack.slam.candidates.CandidateSearch`): they are a lower bound of
the votes an exhaustive comparison gives (:meth:`OrbIndex.votes_exhaustive`, the reference), short of it where the
hash missed a neighbour.

**Cost.** A query costs ``n_tables`` look-ups per descriptor and the Hamming distances of what the buckets hold.
Two things keep that from growing with the run:

* *stop buckets*: ORB's bits are biased, so a few keys collect the descriptors of common patterns from every part of
  the run (at 16 bits over 2000 synthetic keyframes, a bucket of 1800 rows where the mean is 15). A bucket holding
  more than ``max_bucket`` rows says little about where a descriptor comes from, as a stop word of a vocabulary;
  queries pass it by (the descriptor still meets its neighbours in the other tables);
* *growing keys*: once the index holds more than ``rows_per_key`` descriptors per possible key (2^bits), every table
  is keyed by one more bit (the next of its seeded positions) and built again, so the buckets of unrelated
  descriptors stay as small as at the start. This happens at each doubling of the index, so its cost per keyframe
  stays that of an insertion.

A query then reads at most ``n_tables · n · max_bucket`` rows for ``n`` descriptors, whatever the size of the index,
where the exhaustive comparison reads them all. Everything is deterministic: the bit positions come from a fixed
seed, the index depends only on the descriptors added and their order, and the votes not even on that order.
"""

from __future__ import annotations

from array import array
from collections.abc import Iterable

import numpy as np

__all__ = ["OrbIndex", "hamming"]

DESCRIPTOR_BYTES = 32
"""ORB's descriptors: 256 bits."""

MAX_BITS = 40
"""Most bits a key can grow to (2⁴⁰ keys: never reached)."""

_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.uint8)


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances of the rows of ``a`` and ``b`` ((…, 32) uint8, broadcastable), as int32."""
    return _POPCOUNT[np.bitwise_xor(a, b)].sum(axis=-1, dtype=np.int32)


def _hamming_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`hamming` of two (m, 32) uint8 arrays, 64 bits at a time where numpy counts bits (numpy ≥ 2)."""
    if not hasattr(np, "bitwise_count"):
        return hamming(a, b)
    x = np.bitwise_xor(np.ascontiguousarray(a).view(np.uint64), np.ascontiguousarray(b).view(np.uint64))
    return np.bitwise_count(x).sum(axis=1, dtype=np.int32)


def _distinct(values: np.ndarray) -> np.ndarray:
    """The distinct values of an int64 array, sorted (``np.unique``, by a sort)."""
    values = np.sort(values)
    if len(values) < 2:
        return values
    first = np.empty(len(values), bool)
    first[0] = True
    np.not_equal(values[1:], values[:-1], out=first[1:])
    return values[first]


class OrbIndex:
    """Keyframes' ORB descriptors in a multi-table bit-sampling LSH (see the module docstring).

    Parameters
    ----------
    n_tables : int
        Hash tables.
    bits : int
        Bits of a descriptor that key it in each table at the start (at most 40).
    max_distance : int
        A looked-up descriptor votes when within this Hamming distance of the query's (ORB's ratio-test matches
        between views of the same place: median about 30, 90 % below 51).
    max_bucket : int or None
        Queries pass by the buckets holding more rows than this (None: none is passed by).
    rows_per_key : float or None
        The keys grow by one bit when the index holds more than this many descriptors per possible key (None:
        they keep ``bits``).
    seed : int
        Seeds the bit positions of the tables.
    """

    def __init__(
        self, n_tables: int = 16, bits: int = 16, max_distance: int = 48, max_bucket: int | None = 64,
        rows_per_key: float | None = 8.0, seed: int = 0x0B1D,
    ) -> None:
        if not (1 <= bits <= MAX_BITS and n_tables >= 1):
            raise ValueError(f"need 1 ≤ bits ≤ {MAX_BITS} and n_tables ≥ 1, got bits={bits}, n_tables={n_tables}")
        self.n_tables, self.bits, self.max_distance = int(n_tables), int(bits), int(max_distance)
        self.max_bucket = None if max_bucket is None else int(max_bucket)
        self.rows_per_key = None if rows_per_key is None else float(rows_per_key)
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x0BB1]))
        #: (n_tables, MAX_BITS) positions, in 0..255, of the bits of each table's key: the first ``bits`` are used
        self.positions = np.stack([rng.choice(8 * DESCRIPTOR_BYTES, MAX_BITS, replace=False)
                                   for _ in range(self.n_tables)])
        self._tables: list[dict[int, array]] = [{} for _ in range(self.n_tables)]
        self._desc = np.zeros((0, DESCRIPTOR_BYTES), np.uint8)  # rows; capacity grows by doubling
        self._slot = np.zeros(0, np.int64)  # row → slot of its item
        self._rows = 0
        self._ids: list[int] = []  # slot → item id
        self._slot_of: dict[int, int] = {}

    def __len__(self) -> int:
        """Items (keyframes) indexed."""
        return len(self._ids)

    def __contains__(self, item: object) -> bool:
        return item in self._slot_of

    @property
    def n_descriptors(self) -> int:
        return self._rows

    def keys(self, descriptors: np.ndarray, bits: int | None = None) -> np.ndarray:
        """(n, n_tables) int64: each descriptor's key in each table (bit j of a key: the descriptor's bit at the
        table's j-th position, bits numbered from the most significant of byte 0), at ``bits`` (default: now)."""
        desc = _as_descriptors(descriptors)
        pos = self.positions[:, : self.bits if bits is None else int(bits)]
        out = np.zeros((len(desc), self.n_tables), np.int64)
        for j in range(pos.shape[1]):
            bit = (desc[:, pos[:, j] >> 3] >> (7 - (pos[:, j] & 7)).astype(np.uint8)) & 1
            out |= bit.astype(np.int64) << j
        return out

    def add(self, item: int, descriptors: np.ndarray) -> None:
        """Index ``descriptors`` ((n, 32) uint8) under the id ``item`` (an int not yet indexed)."""
        item = int(item)
        if item in self._slot_of:
            raise ValueError(f"item {item} is already in the index")
        desc = _as_descriptors(descriptors)
        slot = len(self._ids)
        self._slot_of[item] = slot
        self._ids.append(item)
        n, start = len(desc), self._rows
        if start + n > len(self._desc):
            cap = max(2 * len(self._desc), start + n, 1024)
            grown = np.zeros((cap, DESCRIPTOR_BYTES), np.uint8)
            grown[:start] = self._desc[:start]
            slots = np.zeros(cap, np.int64)
            slots[:start] = self._slot[:start]
            self._desc, self._slot = grown, slots
        self._desc[start:start + n] = desc
        self._slot[start:start + n] = slot
        self._rows = start + n
        bits = self.bits
        while self.rows_per_key is not None and bits < MAX_BITS and self._rows > self.rows_per_key * 2.0**bits:
            bits += 1
        if bits != self.bits:
            self._rekey(bits)
            return
        for table, column in zip(self._tables, self.keys(desc).T.tolist(), strict=True):
            for row, key in enumerate(column, start):
                bucket = table.get(key)
                if bucket is None:
                    table[key] = array("q", (row,))
                else:
                    bucket.append(row)

    def _rekey(self, bits: int) -> None:
        """Build every table again with keys of ``bits`` bits (the buckets as adding the rows in order would)."""
        self.bits = int(bits)
        keys = self.keys(self._desc[: self._rows])
        for t in range(self.n_tables):
            order = np.argsort(keys[:, t], kind="stable")
            ks = keys[order, t]
            starts = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]])) if len(ks) else np.zeros(0, int)
            ends = np.append(starts[1:], len(ks))
            table: dict[int, array] = {}
            for key, a, b in zip(ks[starts].tolist(), starts.tolist(), ends.tolist(), strict=True):
                bucket = array("q")
                bucket.frombytes(order[a:b].astype(np.int64).tobytes())
                table[key] = bucket
            self._tables[t] = table

    def _allowed_slots(self, allowed: Iterable[int] | None) -> np.ndarray:
        mask = np.zeros(len(self._ids), bool)
        if allowed is None:
            mask[:] = True
        else:
            for item in allowed:
                slot = self._slot_of.get(int(item))
                if slot is not None:
                    mask[slot] = True
        return mask

    def _tally(self, q: np.ndarray, rows: np.ndarray, n_query: int) -> dict[int, int]:
        """Votes from the (query descriptor, indexed row) pairs within ``max_distance``: one per query descriptor
        and item."""
        slot_q = _distinct(self._slot[rows] * n_query + q)
        counts = np.bincount(slot_q // n_query, minlength=len(self._ids))
        return {self._ids[s]: int(counts[s]) for s in np.flatnonzero(counts)}

    def votes(self, descriptors: np.ndarray, allowed: Iterable[int] | None = None) -> dict[int, int]:
        """Item id → votes (query descriptors that met one of the item's within ``max_distance`` in a bucket of at
        most ``max_bucket`` rows), for the items in ``allowed`` (default: all) with at least one vote."""
        desc = _as_descriptors(descriptors)
        if not len(desc) or not self._rows:
            return {}
        mask = self._allowed_slots(allowed)
        limit = self._rows if self.max_bucket is None else self.max_bucket
        buckets: list[array] = []
        owner: list[int] = []
        for table, column in zip(self._tables, self.keys(desc).T.tolist(), strict=True):
            for q, key in enumerate(column):
                bucket = table.get(key)
                if bucket is not None and len(bucket) <= limit:
                    buckets.append(bucket)
                    owner.append(q)
        if not buckets:
            return {}
        sizes = np.fromiter(map(len, buckets), np.int64, count=len(buckets))
        rows = np.frombuffer(b"".join(buckets), np.int64)
        q = np.repeat(np.asarray(owner, np.int64), sizes)
        keep = mask[self._slot[rows]]
        pair = _distinct(q[keep] * self._rows + rows[keep])  # a pair met in several tables counts once
        q, rows = pair // self._rows, pair % self._rows
        near = _hamming_rows(desc[q], self._desc[rows]) <= self.max_distance
        return self._tally(q[near], rows[near], len(desc))

    def votes_exhaustive(self, descriptors: np.ndarray, allowed: Iterable[int] | None = None) -> dict[int, int]:
        """:meth:`votes` with every indexed descriptor compared (no hash, no stop bucket): the reference, and the
        upper bound of :meth:`votes`."""
        desc = _as_descriptors(descriptors)
        if not len(desc) or not self._rows:
            return {}
        rows = np.flatnonzero(self._allowed_slots(allowed)[self._slot[: self._rows]])
        q, r = np.nonzero(hamming(desc[:, None, :], self._desc[rows][None, :, :]) <= self.max_distance)
        return self._tally(q, rows[r], len(desc))

    def shortlist(self, descriptors: np.ndarray, n: int, allowed: Iterable[int] | None = None) -> list[int]:
        """The ``n`` items with the most votes (ties: the smaller id first), each with at least one."""
        votes = self.votes(descriptors, allowed)
        return sorted(votes, key=lambda k: (-votes[k], k))[: max(int(n), 0)]


def _as_descriptors(descriptors: np.ndarray) -> np.ndarray:
    desc = np.ascontiguousarray(descriptors, dtype=np.uint8)
    if desc.ndim != 2 or desc.shape[1] != DESCRIPTOR_BYTES:
        raise ValueError(f"ORB descriptors are (n, {DESCRIPTOR_BYTES}) uint8, got shape {desc.shape}")
    return desc
