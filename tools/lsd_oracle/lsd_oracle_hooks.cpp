// dmtrack's instrumentation hook for the LSD-SLAM oracle (BSD-3-Clause). See lsd_oracle_hooks.h.
#include "lsd_oracle_hooks.h"

void (*lsd_oracle_hook)(int event, void* obj, lsd_slam::Frame* frame) = nullptr;
