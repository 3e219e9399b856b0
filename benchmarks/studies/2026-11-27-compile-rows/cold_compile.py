"""Cold compile of the grey path: ``NUMBA_CACHE_DIR=EMPTY_DIR python cold_compile.py LABEL``.

Prints the seconds ``dmtrack.pipeline.warm_up('gray')`` took (every grey kernel compiled, nothing in the cache) and
the whole process's time after the interpreter started.
"""

import sys
import time

t0 = time.perf_counter()
from dmtrack.pipeline import warm_up  # noqa: E402

s = warm_up("gray", strict=True)
label = sys.argv[1] if len(sys.argv) > 1 else "run"
print(f"{label} warm_up {s:.1f} s, process {time.perf_counter() - t0:.1f} s", flush=True)
