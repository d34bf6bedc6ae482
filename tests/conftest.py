import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import os

from hypothesis import Phase, settings

# "ci": few, fixed examples so the suite stays fast and reproducible; "dev": explore more.
# No shrinking in CI: each example is a full simulation, and shrinking a failure could
# take longer than the whole suite; the failing example is printed as it was found.
settings.register_profile("ci", max_examples=8, deadline=None, derandomize=True,
                          print_blob=True, phases=[Phase.explicit, Phase.generate])
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
