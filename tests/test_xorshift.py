"""The MSL's random number generators and string hash as CasADi expressions
(mcl.compile.xorshift) against integer code written here from the algorithms' definitions
(S. Vigna's xorshift64*, xorshift128+ and xorshift1024*, as Modelica.Math.Random documents
them: 64-bit words held as pairs of 32-bit Integers; A. Partow's AP string hash)."""
import random

import casadi as ca
import numpy as np
import pytest

from mcl.compile import xorshift

M64 = (1 << 64) - 1


def _words(state):
    return [(state[i] & 0xFFFFFFFF) | ((state[i + 1] & 0xFFFFFFFF) << 32) for i in range(0, len(state) - 1, 2)]


def _ints(words):
    return [v - (1 << 32) if v >= 1 << 31 else v for w in words for v in (w & 0xFFFFFFFF, w >> 32)]


def _unit(w):
    """The word read as a signed 64-bit integer, times 2^-64, plus 0.5."""
    return float(w - (1 << 64) if w >= 1 << 63 else w) * 2.0 ** -64 + 0.5


def xorshift64star(state):
    (x,) = _words(state)
    x ^= x >> 12
    x ^= (x << 25) & M64
    x ^= x >> 27
    x = (x * 2685821657736338717) & M64
    return _unit(x), _ints([x])


def xorshift128plus(state):
    a, b = _words(state)
    a ^= (a << 23) & M64
    new = ((a ^ b ^ (a >> 17) ^ (b >> 26)) + b) & M64
    return _unit(new), _ints([b, new])


def xorshift1024star(state):
    s = _words(state[:32])
    p = state[32] & 15
    a = s[p]
    p = (p + 1) & 15
    b = s[p]
    b ^= (b << 31) & M64
    b ^= b >> 11
    a ^= a >> 30
    s[p] = a ^ b
    return _unit((s[p] * 1181783497276652981) & M64), _ints(s) + [p]


@pytest.mark.parametrize("symbol,reference,n", [
    ("ModelicaRandom_xorshift64star", xorshift64star, 2),
    ("ModelicaRandom_xorshift128plus", xorshift128plus, 4),
    ("ModelicaRandom_xorshift1024star", xorshift1024star, 33)])
def test_each_generator_gives_the_integer_algorithms_numbers_symbolically_and_folded(symbol, reference, n):
    rng = random.Random(n)
    s = ca.SX.sym("s", n)
    y, out = xorshift.generate(symbol, s)
    f = ca.Function("f", [s], [y, out])
    for _ in range(50):
        state = [rng.randint(-2 ** 31, 2 ** 31 - 1) for _ in range(n)]
        if n == 33:
            state[32] = rng.randint(-40, 40)          # the index, read modulo 16
        expected_y, expected_state = reference(state)
        got_y, got_state = f(state)
        assert float(got_y) == expected_y
        assert np.array(got_state).ravel().tolist() == expected_state
        folded_y, folded_state = xorshift.generate(symbol, ca.SX(ca.DM(state)))      # constant seeds
        assert folded_y.is_constant() and float(ca.DM(folded_y)) == expected_y
        assert np.array(ca.DM(folded_state)).ravel().tolist() == expected_state


def test_a_state_of_the_wrong_size_is_refused():
    with pytest.raises(ValueError, match="takes a state of 4 Integers, not 3"):
        xorshift.generate("ModelicaRandom_xorshift128plus", ca.SX.sym("s", 3))


def test_the_string_hash_is_the_ap_hash_as_a_signed_integer():
    def ap(text):
        h = 0xAAAAAAAA
        for i, c in enumerate(text.encode()):
            h ^= ((h << 7) ^ (c * (h >> 3))) if i % 2 == 0 else ~((h << 11) + (c ^ (h >> 5)))
            h &= 0xFFFFFFFF
        return h - (1 << 32) if h >= 1 << 31 else h
    for text in ("", "a", "Plant.noise", "Modelica.Blocks.Examples.Noise.UniformNoise.uniformNoise1"):
        assert xorshift.hash_string(text) == ap(text)
    assert xorshift.hash_string("") == 0xAAAAAAAA - (1 << 32)
