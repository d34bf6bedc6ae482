import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import atexit
import os
import shutil
import tempfile

import pytest
from hypothesis import Phase, settings

# "ci": few, fixed examples so the suite stays fast and reproducible; "dev": explore more.
# No shrinking in CI: each example is a full simulation, and shrinking a failure could
# take longer than the whole suite; the failing example is printed as it was found.
settings.register_profile("ci", max_examples=8, deadline=None, derandomize=True,
                          print_blob=True, phases=[Phase.explicit, Phase.generate])
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# "auto" builds nothing, before a run or after long runs (a chain of 48 loops would build
# for 6 s into a cache thrown away with the test), in this process and the ones it starts,
# from the start: module-scoped fixtures run before the per-test fixture below. The tests
# of those rules set it themselves.
os.environ["CMM_DAE_AUTO_BUILD"] = "0"
# and the module-scoped fixtures, which run outside the per-test cache below, use one of
# the session's, never the user's (a sweep's reference table found a build there, ran in
# C, and differed from its dask workers' in the last digits)
os.environ["CMM_DAE_CACHE"] = tempfile.mkdtemp(prefix="cmm_dae_tests_")
atexit.register(shutil.rmtree, os.environ["CMM_DAE_CACHE"], ignore_errors=True)


@pytest.fixture(scope="module")
def module_cache(tmp_path_factory):
    """One build cache for a module's tests (a module that sets ``SHARED_CACHE = True``
    and uses this fixture): the driver and each model compile once for all of them."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("CMM_DAE_CACHE", str(tmp_path_factory.mktemp("cache")))
        yield


@pytest.fixture(autouse=True)
def _empty_compiled_cache(request, tmp_path_factory, monkeypatch):
    """Each test starts with no compiled library built: compiled="auto" (the default) then
    takes the Python path unless the test builds one itself, whatever ran before it on
    this worker (the path a test takes must not depend on the order of the tests), and the
    user's own cache is never written. A module that shares one cache among its tests
    (``SHARED_CACHE = True``) sets it itself."""
    from cmm_dae.integrators import cbuild

    if not getattr(request.module, "SHARED_CACHE", False):
        monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path_factory.mktemp("cmm_cache")))
    cbuild.clear()
    yield
    cbuild.clear()
