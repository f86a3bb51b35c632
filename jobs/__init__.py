"""jobs."""

import estimation.numba_cache  # noqa: F401, I001 (first: numba's cache keyed by the sources, before any kernel)
