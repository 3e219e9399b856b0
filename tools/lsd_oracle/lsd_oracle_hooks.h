// dmtrack's instrumentation hook for the LSD-SLAM oracle (BSD-3-Clause, part of dmtrack's tools).
// build.sh copies this file and lsd_oracle_hooks.cpp into LSD-SLAM's source tree and inserts one call of
// lsd_oracle_hook at five places (see add_hooks.py). The hook only reads state; with no hook set (the
// default) the calls do nothing.
#pragma once

namespace lsd_slam
{
class Frame;
}

enum LsdOracleEvent
{
	LSD_ORACLE_BEFORE_UPDATE = 0,  // DepthMap::updateKeyframe, stereo geometry prepared, before observeDepth
	LSD_ORACLE_AFTER_UPDATE = 1,   // DepthMap::updateKeyframe, after observe / fill holes / regularize
	LSD_ORACLE_BEFORE_CREATE = 2,  // DepthMap::createKeyFrame, old keyframe finalised, before propagation
	LSD_ORACLE_AFTER_CREATE = 3,   // DepthMap::createKeyFrame, after regularisation and rescaling
	LSD_ORACLE_AFTER_TRACK = 4     // SE3Tracker::trackFrame, result stored in the frame (obj = the tracker)
};

// obj: the DepthMap (events 0-3) or the SE3Tracker (event 4); frame: the reference / new keyframe / tracked frame
extern void (*lsd_oracle_hook)(int event, void* obj, lsd_slam::Frame* frame);
