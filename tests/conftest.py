"""Shared fixtures."""

import matplotlib

matplotlib.use("Agg")


from dataclasses import dataclass  # noqa: E402

import pytest  # noqa: E402


@dataclass
class CliResult:
    """Exit code and captured output of one ``hptrack`` command."""

    code: int
    out: str
    err: str

    @property
    def error_lines(self) -> list[str]:
        return [line for line in self.err.splitlines() if line.strip()]

    def refused(self, *needles: str) -> None:
        """Assert a refusal: exit code 2 and one line on stderr holding every needle."""
        assert self.code == 2, (self.code, self.out, self.err)
        assert "Traceback" not in self.err and len(self.error_lines) == 1, self.err
        for needle in needles:
            assert needle in self.error_lines[0], self.error_lines[0]


@pytest.fixture
def cli(capsys):
    """Run ``hptrack ARGS...`` through its real entry point (exit codes and error policy
    included) and return a :class:`CliResult`."""
    from hptrack.cli.app import main

    def run(*args) -> CliResult:
        capsys.readouterr()
        with pytest.raises(SystemExit) as exit_:
            main([str(a) for a in args])
        captured = capsys.readouterr()
        return CliResult(exit_.value.code, captured.out, captured.err)

    return run


# The fuzz suite's budgets (tests/*/test_*fuzz*.py): a small fixed one in CI ("fuzz-ci", the
# default) and a long run by hand: HPTRACK_FUZZ=fuzz-long python3 -m pytest -k fuzz.
# A fuzz test is decorated with ``@settings.get_profile(FUZZ_PROFILE)``; other tests keep theirs.
from hypothesis import HealthCheck, settings  # noqa: E402

_SLOW_OK = [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
settings.register_profile("fuzz-ci", max_examples=30, deadline=None, suppress_health_check=_SLOW_OK)
settings.register_profile(
    "fuzz-long", max_examples=1000, deadline=None, suppress_health_check=_SLOW_OK
)
