import time,sys
t0=time.perf_counter()
from dmtrack.pipeline import warm_up
s=warm_up('gray', strict=True)
print(f"{sys.argv[1]} warm_up {s:.1f} s, process {time.perf_counter()-t0:.1f} s", flush=True)
