"""The random streams of scikit-learn's forests, compiled (numba): numpy's legacy MT19937 and
scikit-learn's ``rand_r``.

What a ``RandomForestClassifier(random_state=seed)`` draws (numpy 1.26-2.x legacy
``RandomState``, scikit-learn 1.9.1):

- ``RandomState(s)`` for an integer ``s`` in [0, 2**32) is ``mt19937_seed`` (Knuth's
  ``init_genrand``); outputs are the tempered words of ``mt19937_gen`` blocks of 624.
- ``randint(low, high)`` (legacy, ``int64``) is masked rejection on 32-bit outputs
  (``random_bounded_uint64_fill`` with ``use_masked``): ``rng = high - low - 1``; no draw
  when ``rng == 0``; else draw ``v = next_uint32() & mask`` (``mask`` the smallest
  ``2**k - 1 >= rng``) until ``v <= rng``; the result is ``low + v``.
- Tree seeds: ``randint(2**31 - 1)`` per tree from ``RandomState(seed)``
  (``_set_random_states``); tree i's bootstrap: ``RandomState(s_i).randint(0, N, N_boot)``;
  its splitter seed: the first ``randint(0, 2**31 - 1)`` of a fresh ``RandomState(s_i)``
  (``Splitter.init``), i.e. the same stream's first accepted draw.
- The splitter's own generator (sklearn/utils/_random.pxd ``our_rand_r``): 32-bit xorshift
  13/17/5 (a zero state becomes 1), output ``state % 2**31``; ``rand_int(low, high)`` is
  ``low + our_rand_r() % (high - low)`` (sklearn/tree/_utils.pyx).

State: ``mt: (625,)`` int64, words 0..623 and the read position at ``mt[624]``; every value
is kept in [0, 2**32) in int64 arithmetic. For speed, not for other draws: ``mt_seed4``
seeds four states at once, ``draw_bootstrap`` is ``randint(0, N)`` repeated with the read
position in a register, and the functions called per draw are ``inline="always"`` (a numba
call that passes an array pays reference counting). ``tests/learn/test_engine.py`` checks the streams
against numpy's.
"""
from __future__ import annotations

import numpy as np
from numba import njit

N_MT = 624
MASK32 = 0xFFFFFFFF
RAND_R_MAX = 0x7FFFFFFF  # sklearn/tree/_utils.pxd: 2**31 - 1
MAX_INT = 0x7FFFFFFF  # sklearn.ensemble._forest.MAX_INT = np.iinfo(np.int32).max


@njit(cache=True)
def mt_seed(mt, seed):
    """``mt19937_seed``: ``mt: (625,)`` int64 set from ``seed`` in [0, 2**32)."""
    s = seed & MASK32
    mt[0] = s
    for i in range(1, N_MT):
        s = (1812433253 * (s ^ (s >> 30)) + i) & MASK32
        mt[i] = s
    mt[N_MT] = N_MT  # the first draw runs mt19937_gen


@njit(cache=True)
def mt_seed4(mts, s0, s1, s2, s3):
    """``mt_seed`` of four states at once, ``mts: (4, 625)`` int64 from seeds s0..s3: one
    seeding is a chain of 623 dependent multiplications (latency-bound); four independent
    chains interleaved take about the time of one."""
    a, b, c, d = s0 & MASK32, s1 & MASK32, s2 & MASK32, s3 & MASK32
    mts[0, 0], mts[1, 0], mts[2, 0], mts[3, 0] = a, b, c, d
    for i in range(1, N_MT):
        a = (1812433253 * (a ^ (a >> 30)) + i) & MASK32
        b = (1812433253 * (b ^ (b >> 30)) + i) & MASK32
        c = (1812433253 * (c ^ (c >> 30)) + i) & MASK32
        d = (1812433253 * (d ^ (d >> 30)) + i) & MASK32
        mts[0, i], mts[1, i], mts[2, i], mts[3, i] = a, b, c, d
    for g in range(4):
        mts[g, N_MT] = N_MT


@njit(cache=True)
def mt_gen(mt):
    """``mt19937_gen``: the next 624 words, in place (numpy's three loops)."""
    for i in range(N_MT - 397):
        y = (mt[i] & 0x80000000) | (mt[i + 1] & 0x7FFFFFFF)
        mt[i] = mt[i + 397] ^ (y >> 1) ^ ((y & 1) * 0x9908B0DF)
    for i in range(N_MT - 397, N_MT - 1):
        y = (mt[i] & 0x80000000) | (mt[i + 1] & 0x7FFFFFFF)
        mt[i] = mt[i + 397 - N_MT] ^ (y >> 1) ^ ((y & 1) * 0x9908B0DF)
    y = (mt[N_MT - 1] & 0x80000000) | (mt[0] & 0x7FFFFFFF)
    mt[N_MT - 1] = mt[396] ^ (y >> 1) ^ ((y & 1) * 0x9908B0DF)
    mt[N_MT] = 0


@njit(cache=True)
def temper(y):
    """MT19937's output tempering of one word."""
    y ^= y >> 11
    y ^= (y << 7) & 0x9D2C5680
    y ^= (y << 15) & 0xEFC60000
    y ^= y >> 18
    return y & MASK32


@njit(cache=True, inline="always")
def mt_next(mt):
    """The next tempered 32-bit output (``genrand_int32``) as int64."""
    if mt[N_MT] >= N_MT:
        mt_gen(mt)
    y = mt[mt[N_MT]]
    mt[N_MT] += 1
    return temper(y)


@njit(cache=True)
def first_randint(mt, low, high):
    """What ``randint(low, high)`` of a freshly seeded ``mt`` gives, without consuming it:
    ``mt`` is generated (``mt_gen``) if it was not, and read from word 0 (an exact peek only
    right after ``mt_seed``). Saves seeding a second ``RandomState(s_i)`` per tree."""
    if mt[N_MT] >= N_MT:
        mt_gen(mt)
    rng = high - low - 1
    if rng == 0:
        return low
    mask = mask_of(rng)
    k = 0
    while True:
        if k == N_MT:  # (probability ~2**-19000) fall back to a real stream
            return -1
        v = temper(mt[k]) & mask
        k += 1
        if v <= rng:
            return low + v


@njit(cache=True)
def mask_of(rng):
    """The smallest ``2**k - 1 >= rng`` (numpy's ``gen_mask``)."""
    m = rng
    m |= m >> 1
    m |= m >> 2
    m |= m >> 4
    m |= m >> 8
    m |= m >> 16
    m |= m >> 32
    return m


@njit(cache=True, inline="always")
def randint(mt, low, high):
    """Legacy ``RandomState.randint(low, high)`` (one draw, high - low <= 2**32)."""
    rng = high - low - 1
    if rng == 0:
        return low
    mask = mask_of(rng)
    while True:
        v = mt_next(mt) & mask
        if v <= rng:
            return low + v


@njit(cache=True)
def draw_bootstrap(mt, wt, n, n_draws):
    """``wt[randint(mt, 0, n)] += 1.0`` for ``n_draws`` draws, the stream's read position
    kept in a register rather than in ``mt[624]`` (~6x faster per draw)."""
    rng = n - 1
    if rng == 0:  # randint draws nothing then
        for _ in range(n_draws):
            wt[0] += 1.0
        return
    mask = mask_of(rng)
    pos = mt[N_MT]
    for _ in range(n_draws):
        while True:
            if pos >= N_MT:
                mt_gen(mt)
                pos = 0
            v = temper(mt[pos]) & mask
            pos += 1
            if v <= rng:
                break
        wt[v] += 1.0
    mt[N_MT] = pos


@njit(cache=True)
def draw_subsample(mt, wt, n, m):
    """``forests.subsample_weights``: a partial Fisher-Yates shuffle of 0..n-1 by legacy
    ``randint(i, n)`` for i < m, weight 1.0 on the first m (``wt`` zeroed first)."""
    idx = np.arange(n)
    for i in range(m):
        j = randint(mt, i, n)
        t = idx[i]
        idx[i] = idx[j]
        idx[j] = t
    wt[:] = 0.0
    for i in range(m):
        wt[idx[i]] = 1.0


@njit(cache=True, inline="always")
def rand_r(state):
    """``our_rand_r`` on ``state: (1,)`` int64 (a uint32 value); returns the 31-bit output."""
    s = state[0]
    if s == 0:
        s = 1
    s ^= (s << 13) & MASK32
    s ^= s >> 17
    s ^= (s << 5) & MASK32
    state[0] = s
    return s & RAND_R_MAX


@njit(cache=True, inline="always")
def rand_int(state, low, high):
    """``rand_int(low, high, state)``: an integer in [low, high)."""
    return low + rand_r(state) % (high - low)
