import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import math
import os

import pytest
from hypothesis import Phase, settings

# "ci": few, fixed examples so the suite stays fast and reproducible; "dev": explore more.
# No shrinking in CI: each example is a full simulation, and shrinking a failure could
# take longer than the whole suite; the failing example is printed as it was found.
settings.register_profile("ci", max_examples=8, deadline=None, derandomize=True,
                          print_blob=True, phases=[Phase.explicit, Phase.generate])
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(autouse=True)
def _empty_compiled_cache(request, tmp_path_factory, monkeypatch):
    """Each test starts with no compiled library built: compiled="auto" (the default) then
    takes the Python path unless the test builds one itself, whatever ran before it on
    this worker (the path a test takes must not depend on the order of the tests), and the
    user's own cache is never written. A module that shares one cache among its tests
    (``SHARED_CACHE = True``) sets it itself."""
    from cmm_dae.integrators import csegment

    if not getattr(request.module, "SHARED_CACHE", False):
        monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path_factory.mktemp("cmm_cache")))
    # no background builds after long runs (a chain of 48 loops would build for 6 s into
    # a cache thrown away with the test); the tests of that rule set it themselves
    monkeypatch.setattr(csegment, "AUTO_BUILD_AFTER", math.inf)
    csegment.clear()
    yield
    csegment.clear()
