"""The MSL's external C functions for random numbers (``Modelica.Math.Random``: the xorshift64*,
xorshift128+ and xorshift1024* generators of S. Vigna) and for a string's hash
(``Modelica.Utilities.Strings.hashString``: a noise block's automatic local seed), as CasADi
expressions. A model with noise blocks stays one symbolic model, generated as C into the FMU
with no external code.

The generators work on 64-bit words, which the Modelica side holds as pairs of Integers (the
low and the high 32 bits, as the C functions read them). A word is held here as its 64 bits,
each an SX of value 0 or 1: exclusive or and shifts are then exact in double arithmetic. Sums and
products go through four 16-bit limbs, whose products stay below 2^53. With constant seeds
(an initial state) everything folds to numbers while the model is built.
"""
from __future__ import annotations

import casadi as ca

BITS = 64
#: 2^-64: a word read as a signed 64-bit integer, scaled into (0, 1] (+ 0.5)
_INV_2_64 = 2.0 ** -64


def _bits_of_int32(v) -> list:
    """The 32 bits (least significant first) of a signed 32-bit Integer's value ``v``."""
    u = v + 2.0 ** 32 * (v < 0)
    bits = []
    for _ in range(32):
        q = ca.floor(u / 2)
        bits.append(u - 2 * q)
        u = q
    return bits


def _word(lo, hi) -> list:
    return _bits_of_int32(lo) + _bits_of_int32(hi)


def _unsigned(bits: list):
    out = ca.SX(0)
    for k, b in enumerate(bits):
        out = out + b * 2.0 ** k
    return out


def _int32_pair(bits: list) -> list:
    """(low, high) halves of a word as signed 32-bit Integers."""
    return [_unsigned(half) - 2.0 ** 32 * half[31] for half in (bits[:32], bits[32:])]


def _xor(a: list, b: list) -> list:
    return [x + y - 2 * x * y for x, y in zip(a, b)]


def _shl(a: list, n: int) -> list:
    return [ca.SX(0)] * n + a[:BITS - n]


def _shr(a: list, n: int) -> list:
    return a[n:] + [ca.SX(0)] * n


def _limbs(a: list) -> list:
    return [_unsigned(a[16 * i:16 * i + 16]) for i in range(4)]


def _bits_of_limbs(limbs: list) -> list:
    """The word whose 16-bit limbs are ``limbs`` (each may exceed 16 bits: the excess carried
    into the next, and out of the last dropped: modulo 2^64)."""
    bits, carry = [], ca.SX(0)
    for limb in limbs:
        v = limb + carry
        for _ in range(16):
            q = ca.floor(v / 2)
            bits.append(v - 2 * q)
            v = q
        carry = v
    return bits


def _add(a: list, b: list) -> list:
    return _bits_of_limbs([x + y for x, y in zip(_limbs(a), _limbs(b))])


def _times(a: list, c: int) -> list:
    """``a`` times the constant ``c``, modulo 2^64."""
    al = _limbs(a)
    cl = [(c >> (16 * j)) & 0xFFFF for j in range(4)]
    return _bits_of_limbs([sum((al[i] * cl[k - i] for i in range(k + 1)), ca.SX(0)) for k in range(4)])


def _uniform(bits: list):
    """The word as a signed 64-bit integer times 2^-64, plus 0.5: a number in (0, 1]."""
    lo, hi = _unsigned(bits[:32]), _unsigned(bits[32:]) - 2.0 ** 32 * bits[63]
    return (hi * 2.0 ** 32 + lo) * _INV_2_64 + 0.5


def _words(state, n: int) -> list:
    return [_word(state[2 * i], state[2 * i + 1]) for i in range(n)]


def _pairs(words: list) -> list:
    return [v for w in words for v in _int32_pair(w)]


def xorshift64star(state) -> tuple:
    x = _word(state[0], state[1])
    x = _xor(x, _shr(x, 12))
    x = _xor(x, _shl(x, 25))
    x = _xor(x, _shr(x, 27))
    x = _times(x, 2685821657736338717)
    return _uniform(x), _int32_pair(x)


def xorshift128plus(state) -> tuple:
    s1, s0 = _words(state, 2)
    s1 = _xor(s1, _shl(s1, 23))
    new = _add(_xor(_xor(s1, s0), _xor(_shr(s1, 17), _shr(s0, 26))), s0)
    return _uniform(new), _pairs([s0, new])


def _select(words: list, p) -> list:
    """words[p] for an SX index p in 0..len - 1."""
    return [sum(((p == j) * w[k] for j, w in enumerate(words)), ca.SX(0)) for k in range(BITS)]


def xorshift1024star(state) -> tuple:
    s = _words(state, 16)
    p = state[32] - 16 * ca.floor(state[32] / 16)          # p & 15
    s0 = _select(s, p)
    p = p + 1 - 16 * (p == 15)
    s1 = _select(s, p)
    s1 = _xor(s1, _shl(s1, 31))
    s1 = _xor(s1, _shr(s1, 11))
    s0 = _xor(s0, _shr(s0, 30))
    new = _xor(s0, s1)
    s = [[ca.if_else(p == j, n, b) for n, b in zip(new, w)] for j, w in enumerate(s)]
    return _uniform(_times(new, 1181783497276652981)), _pairs(s) + [p]


#: external symbol -> (function of the state vector -> (result, new state), the state's size)
GENERATORS = {"ModelicaRandom_xorshift64star": (xorshift64star, 2),
              "ModelicaRandom_xorshift128plus": (xorshift128plus, 4),
              "ModelicaRandom_xorshift1024star": (xorshift1024star, 33)}


_built: dict[str, ca.Function] = {}


def generate(symbol: str, state: ca.SX) -> tuple[ca.SX, ca.SX]:
    """(the random number, the new state vector) of generator ``symbol`` from ``state``."""
    f, n = GENERATORS[symbol]
    if state.numel() != n:
        raise ValueError(f"{symbol} takes a state of {n} Integers, not {state.numel()}")
    if symbol not in _built:       # (written out once: a call is then evaluated or inlined)
        s = ca.SX.sym("s", n)
        y, out = f(ca.vertsplit(s))
        # (a word's halves are read for both the number and the new state: computed once)
        _built[symbol] = ca.Function(symbol, [s], ca.cse([ca.SX(y), ca.vertcat(*out)]))
    state = ca.vec(state)
    if state.is_constant():
        return tuple(ca.SX(v) for v in _built[symbol](ca.DM(state)))
    return tuple(_built[symbol](state))


def hash_string(text: str) -> int:
    """Modelica.Utilities.Strings.hashString: A. Partow's AP hash of the UTF-8 bytes, as a
    signed 32-bit Integer."""
    m = 0xFFFFFFFF
    h = 0xAAAAAAAA
    for i, c in enumerate(text.encode("utf-8")):
        if i % 2 == 0:
            h ^= ((h << 7) ^ (c * (h >> 3))) & m
        else:
            h ^= ~((h << 11) + (c ^ (h >> 5))) & m
        h &= m
    return h - (1 << 32) if h >= 1 << 31 else h
