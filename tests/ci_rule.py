"""Under CI=true no test may skip (issue 39, item 4): a skip (a module's importorskip, a skipif
mark, a pytest.skip at run time) is reported as a failure with its reason.  A plugin module:
tests/conftest.py registers its hooks for this suite, tests/test_ci_skips.py runs it alone."""

import os

import pytest


def in_ci() -> bool:
    """CI=true (as CI services and .ci/run set it): every test must run, none may skip."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def _skip_is_failure(report) -> None:
    if report.skipped and in_ci() and not hasattr(report, "wasxfail"):
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) and len(longrepr) == 3 else longrepr
        reason = str(reason).removeprefix("Skipped: ")
        report.outcome = "failed"
        report.longrepr = f"skipped under CI=true, where every test must run: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    _skip_is_failure(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _skip_is_failure(outcome.get_result())
