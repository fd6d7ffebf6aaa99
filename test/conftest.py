"""Shared pytest set-up: keep ROS traffic on localhost, in domains of our own.

Every test process gets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; the
``ros_domain`` fixture hands each test a fresh ROS_DOMAIN_ID (derived from the
pytest process id, so concurrent runs on one machine rarely meet) and sets it
in ``os.environ`` for the test and the processes it starts.

Property tests (hypothesis) run derandomized, without an example database: the
same cases on every machine and every run, so a fresh clone passes or fails
the same way each time. A long random search belongs in ``bench/``; set
``HYPOTHESIS_PROFILE=random`` to explore locally, and turn what it finds into a
plain regression test.
"""

from __future__ import annotations

import itertools
import os

import pytest
from hypothesis import settings

settings.register_profile('fixed', derandomize=True, database=None, print_blob=True)
settings.register_profile('random', derandomize=False, print_blob=True)
settings.load_profile(os.environ.get('HYPOTHESIS_PROFILE', 'fixed'))

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# Domain ids 1..100 are safe for the default port mapping; 8 per run. An exported
# ROS_DOMAIN_ID starts the block (two users on one host keep apart); else offset by pid.
_EXPORTED = os.environ.get('ROS_DOMAIN_ID', '')
_BASE = int(_EXPORTED) if _EXPORTED.isdigit() and int(_EXPORTED) <= 93 \
    else 1 + (os.getpid() % 12) * 8
_domains = itertools.cycle(range(_BASE, _BASE + 8))


def next_domain_id() -> int:
    """A ROS_DOMAIN_ID for one test (cycles through this run's block of 8)."""
    return next(_domains)


@pytest.fixture
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A fresh ROS_DOMAIN_ID, set in os.environ for the test and its child processes."""
    domain = next_domain_id()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(domain))
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return domain
