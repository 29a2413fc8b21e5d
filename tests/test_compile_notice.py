"""A live command says when numba compiles rtsar's kernels (rtsar.app.compile_notice): a
correlator's first run compiled for 10-20 s after "measuring the work …" with no word."""

import numba

from rtsar.app.compile_notice import compile_notice


def test_each_rtsar_module_compiled_is_told_once_and_nothing_else():
    def add_one(x):
        return x + 1

    def double(x):
        return x * 2

    add_one.__module__ = "rtsar.ccd.fake_kernels"  # as if it were one of rtsar's
    ours, theirs = numba.njit(add_one), numba.njit(double)  # no cache: each call compiles
    lines = []
    with compile_notice(lines.append):
        assert ours(1) == 2 and ours(2.5) == 3.5  # two compilations of one module
        assert theirs(3) == 6  # not rtsar's
    assert len(lines) == 1, lines
    assert "rtsar.ccd.fake_kernels" in lines[0] and "numba is compiling" in lines[0]
    assert ours(1j) == 1 + 1j  # compiled after the block: not told
    assert len(lines) == 1


def test_a_kernel_already_compiled_is_not_told():
    def triple(x):
        return x * 3

    triple.__module__ = "rtsar.ccd.fake_kernels"
    kernel = numba.njit(triple)
    kernel(2)  # compiled before the block
    lines = []
    with compile_notice(lines.append):
        assert kernel(4) == 12
    assert lines == []
