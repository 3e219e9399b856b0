// lsd_oracle: runs upstream LSD-SLAM (tum-vision/lsd_slam d1e6f0e, built by build.sh) on an image sequence the
// way the ROS program dataset_slam does, without ROS, and writes what dmtrack compares itself with.
//
// This file is dmtrack's own (BSD-3-Clause); it links against LSD-SLAM (GPL-3.0), which is never part of
// dmtrack's repository. It reads LSD-SLAM's private state through the read-only hook added by add_hooks.py.
//
//   lsd_oracle files=LIST|DIR calib=CALIB out=PREFIX [slam=0] [mt=0] [end=N] [seed=S]
//              [initdepth=FILE] [dumpinit=FILE] [dump=DIR] [dumpframes=A:B] [dumpkf=0|1]
//              [affine=0] [kfusage=4] [kfdist=3] [mingrad=5] [noise=4]
//
// files      a folder (every file in it, sorted, as upstream) or a text file listing one image per line
// calib      LSD-SLAM calibration file (4 lines; a pinhole is "fx/w fy/h (cx+0.5)/w (cy+0.5)/h 0")
// out        writes PREFIX.txt (every frame, TUM, camera-to-world, timestamp = frame index), PREFIX_kf.txt
//            (keyframes) and PREFIX_trace.jsonl (one JSON object per frame, see README.md); with slam=1 the
//            poses are those after upstream's finalize() (final optimisation) and PREFIX_graph.txt lists the
//            pose graph's constraints (keyframe pairs, odometry or loop)
// slam/mt    doSlam and multiThreading (default 0/0: pure VO, single-threaded mapping, deterministic)
// seed       srand(seed) before the random initialisation (default: not called, i.e. glibc's seed 1)
// initdepth  replace the random initial inverse depth by this file (H*W float32, row-major; <= 0 or NaN
//            marks "no hypothesis"); valid pixels get variance VAR_RANDOM_INIT_INITIAL and validity 20 as
//            upstream's random initialisation
// dumpinit   write the initial inverse depth actually used (same format, -1 where invalid)
// dump       folder for binary state dumps: with dumpframes=A:B the depth map before and after mapping each
//            frame A..B (pre_/post_NNNNNN.bin), the tracker's level-1 refPixelWasGood flags
//            (good_NNNNNN.bin, uint8), the stereo pose (stereo_NNNNNN.txt), the tracking reference's point
//            clouds of levels 1-4 (track_NNNNNN.bin: per level an int32 count, then x y z I var pixel-index as
//            float32 per point) and the tracker's initial keyframe->frame pose (trackinit_NNNNNN.txt); with
//            dumpkf=1 every keyframe
//            at creation (kfnew_NNNNNN.bin), the old one finalised (kfold_NNNNNN.bin, NNNNNN = new id), the
//            new keyframe's tracked pose (kfpose_NNNNNN.txt) and its refPixelWasGood flags (kfgood_NNNNNN.bin).
//            A state dump is H*W*8 float32: valid, blacklisted, nextStereoFrameMinID, validity, idepth,
//            idepth_var, idepth_smoothed, idepth_var_smoothed.
// affine..   parameters; defaults are the ROS dynamic-reconfigure start values (cfg/LSDParams.cfg), which
//            differ from settings.cpp in KFUsageWeight (4, not 3), KFDistWeight (3, not 4) and
//            useAffineLightningEstimation (off, not on).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <dirent.h>
#include <unistd.h>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <boost/thread.hpp>
#include <opencv2/opencv.hpp>

// upstream headers with their private members readable (the library itself is compiled unchanged)
#include "util/SophusUtil.h"
#include "GlobalMapping/g2oTypeSim3Sophus.h"
#define private public
#define protected public
#include "SlamSystem.h"
#include "DataStructures/Frame.h"
#include "DepthEstimation/DepthMap.h"
#include "DepthEstimation/DepthMapPixelHypothesis.h"
#include "GlobalMapping/KeyFrameGraph.h"
#include "Tracking/SE3Tracker.h"
#include "Tracking/TrackingReference.h"
#include "util/Undistorter.h"
#include "util/settings.h"
#undef private
#undef protected
#include "lsd_oracle_hooks.h"

using namespace lsd_slam;

namespace
{
struct Args
{
	std::map<std::string, std::string> kv;
	std::string get(const std::string& k, const std::string& def = "") const
	{
		auto it = kv.find(k);
		return it == kv.end() ? def : it->second;
	}
	bool has(const std::string& k) const { return kv.count(k) > 0; }
};

// everything the hooks gather for the frame being processed
struct FrameRecord
{
	int frame = -1;
	int parent = -1;
	bool tracked = false;
	bool diverged = false;
	bool trackingGood = false;
	float residual = 0, itr = 0, usage = 0, good = 0, bad = 0;
	int parentMapped = -1;
	float parentMeanIdepth = NAN;
	float Tfk[12] = {0};  // keyframe -> frame (referenceToFrame), 3x4 row-major
};

std::mutex g_mutex;
FrameRecord g_rec;
// JSON fragments from the depth-map hooks, by the frame they concern: mapping runs in LSD-SLAM's mapping
// thread and, even with blockUntilMapped, overlaps the tracking of the next frame
std::map<int, std::string> g_mapping;
std::string g_dumpDir;
int g_dumpFirst = 1, g_dumpLast = 0;
bool g_dumpKf = false;
int g_width = 0, g_height = 0;
SlamSystem* g_system = nullptr;

bool inDumpRange(int id) { return !g_dumpDir.empty() && id >= g_dumpFirst && id <= g_dumpLast; }

std::string path6(const std::string& stem, int id, const char* ext)
{
	char buf[64];
	snprintf(buf, sizeof(buf), "%s_%06d%s", stem.c_str(), id, ext);
	return g_dumpDir + "/" + buf;
}

void dumpState(const DepthMapPixelHypothesis* dm, const std::string& file)
{
	std::vector<float> out((size_t)g_width * g_height * 8);
	for(int i = 0; i < g_width * g_height; i++)
	{
		const DepthMapPixelHypothesis& p = dm[i];
		float* o = &out[(size_t)i * 8];
		o[0] = p.isValid ? 1.f : 0.f;
		o[1] = (float)p.blacklisted;
		o[2] = p.nextStereoFrameMinID;
		o[3] = (float)p.validity_counter;
		o[4] = p.idepth;
		o[5] = p.idepth_var;
		o[6] = p.idepth_smoothed;
		o[7] = p.idepth_var_smoothed;
	}
	FILE* f = fopen(file.c_str(), "wb");
	if(!f) { fprintf(stderr, "lsd_oracle: cannot write %s\n", file.c_str()); exit(2); }
	fwrite(out.data(), sizeof(float), out.size(), f);
	fclose(f);
}

// summary of a depth map: valid hypotheses, tracking pixels (valid, smoothed idepth >= -0.05, as
// Frame::setDepth), their mean inverse depth, blacklisted pixels, histogram of log10(var_smoothed)
std::string depthStats(const DepthMapPixelHypothesis* dm)
{
	int nValid = 0, nTrack = 0, nBlack = 0;
	double sum = 0;
	int hist[8] = {0};  // log10 var: < -6, [-6,-5), ..., [-1, 0), >= 0
	for(int i = 0; i < g_width * g_height; i++)
	{
		const DepthMapPixelHypothesis& p = dm[i];
		if(p.blacklisted < MIN_BLACKLIST) nBlack++;
		if(!p.isValid) continue;
		nValid++;
		if(p.idepth_smoothed >= -0.05f)
		{
			nTrack++;
			sum += p.idepth_smoothed;
			double lv = std::log10(std::max(1e-30, (double)p.idepth_var_smoothed));
			int b = lv < -6 ? 0 : (lv >= 0 ? 7 : (int)std::floor(lv) + 7);
			hist[b]++;
		}
	}
	std::ostringstream s;
	s << "{\"valid\": " << nValid << ", \"tracking\": " << nTrack << ", \"blacklisted\": " << nBlack
	  << ", \"mean_idepth\": " << (nTrack ? sum / nTrack : 0.0) << ", \"var_hist\": [";
	for(int b = 0; b < 8; b++) s << hist[b] << (b < 7 ? ", " : "]}");
	return s.str();
}

void writeMatrix(const std::string& file, const Sim3& S, float itr)
{
	std::ofstream f(file);
	f.precision(17);
	Eigen::Matrix<double, 3, 4> M = S.matrix3x4();
	for(int r = 0; r < 3; r++)
		f << M(r, 0) << " " << M(r, 1) << " " << M(r, 2) << " " << M(r, 3) << "\n";
	f << "scale " << S.scale() << "\nitr " << itr << "\n";
}

void hook(int event, void* obj, Frame* frame)
{
	std::lock_guard<std::mutex> lock(g_mutex);
	if(event == LSD_ORACLE_AFTER_TRACK)
	{
		SE3Tracker* tr = (SE3Tracker*)obj;
		g_rec.frame = frame->id();
		g_rec.parent = frame->getTrackingParent()->id();
		g_rec.diverged = tr->diverged;
		g_rec.trackingGood = tr->trackingWasGood;
		g_rec.residual = tr->lastResidual;
		g_rec.itr = frame->initialTrackedResidual;
		g_rec.usage = tr->pointUsage;
		g_rec.good = tr->lastGoodCount;
		g_rec.bad = tr->lastBadCount;
		g_rec.parentMapped = frame->getTrackingParent()->numMappedOnThisTotal;
		g_rec.parentMeanIdepth = frame->getTrackingParent()->meanIdepth;
		SE3 refToFrame = se3FromSim3(frame->pose->thisToParent_raw).inverse();
		Eigen::Matrix<double, 3, 4> M = refToFrame.matrix3x4();
		for(int r = 0; r < 3; r++)
			for(int c = 0; c < 4; c++) g_rec.Tfk[r * 4 + c] = (float)M(r, c);
		if(inDumpRange(frame->id()))
		{
			// the tracking reference as used: per level 1..4 the point count, then per point
			// x, y, z (keyframe camera), keyframe intensity, inverse-depth variance, pixel index
			TrackingReference* ref = g_system->trackingReference;
			FILE* f = fopen(path6("track", frame->id(), ".bin").c_str(), "wb");
			for(int lvl = 1; lvl < PYRAMID_LEVELS; lvl++)
			{
				int n = ref->numData[lvl];
				fwrite(&n, sizeof(int), 1, f);
				for(int i = 0; i < n; i++)
				{
					float rec[6] = {ref->posData[lvl][i][0], ref->posData[lvl][i][1], ref->posData[lvl][i][2],
					                ref->colorAndVarData[lvl][i][0], ref->colorAndVarData[lvl][i][1],
					                (float)(ref->pointPosInXYGrid[lvl] ? ref->pointPosInXYGrid[lvl][i] : -1)};
					fwrite(rec, sizeof(float), 6, f);
				}
			}
			fclose(f);
		}
		if(inDumpRange(frame->id()) && frame->data.refPixelWasGood)
		{
			int n = (g_width >> SE3TRACKING_MIN_LEVEL) * (g_height >> SE3TRACKING_MIN_LEVEL);
			FILE* f = fopen(path6("good", frame->id(), ".bin").c_str(), "wb");
			fwrite(frame->data.refPixelWasGood, 1, n, f);
			fclose(f);
		}
		return;
	}
	DepthMap* map = (DepthMap*)obj;
	switch(event)
	{
	case LSD_ORACLE_BEFORE_UPDATE:
		if(inDumpRange(frame->id()))
		{
			dumpState(map->currentDepthMap, path6("pre", frame->id(), ".bin"));
			writeMatrix(path6("stereo", frame->id(), ".txt"), frame->pose->thisToParent_raw, frame->initialTrackedResidual);
		}
		break;
	case LSD_ORACLE_AFTER_UPDATE:
	{
		// LSD-SLAM's own stage timings (exponential averages, 0.9 old + 0.1 new, in ms), then the map's statistics
		std::ostringstream ms;
		ms << ", \"ms\": {\"observe\": " << map->msObserve << ", \"regularize\": " << map->msRegularize
		   << ", \"fill_holes\": " << map->msFillHoles << ", \"propagate\": " << map->msPropagate
		   << ", \"create\": " << map->msCreate << ", \"finalize\": " << map->msFinalize << "}";
		g_mapping[frame->id()] += ms.str() + ", \"update\": " + depthStats(map->currentDepthMap);
		if(inDumpRange(frame->id())) dumpState(map->currentDepthMap, path6("post", frame->id(), ".bin"));
		break;
	}
	case LSD_ORACLE_BEFORE_CREATE:
		g_mapping[frame->id()] += ", \"finalized\": " + depthStats(map->currentDepthMap);
		if(g_dumpKf && !g_dumpDir.empty())
		{
			dumpState(map->currentDepthMap, path6("kfold", frame->id(), ".bin"));
			writeMatrix(path6("kfpose", frame->id(), ".txt"), frame->pose->thisToParent_raw, frame->initialTrackedResidual);
			if(frame->data.refPixelWasGood)
			{
				int n = (g_width >> SE3TRACKING_MIN_LEVEL) * (g_height >> SE3TRACKING_MIN_LEVEL);
				FILE* f = fopen(path6("kfgood", frame->id(), ".bin").c_str(), "wb");
				fwrite(frame->data.refPixelWasGood, 1, n, f);
				fclose(f);
			}
		}
		break;
	case LSD_ORACLE_AFTER_CREATE:
	{
		std::ostringstream s;
		s << ", \"created\": " << depthStats(map->currentDepthMap)
		  << ", \"rescale\": " << frame->pose->thisToParent_raw.scale();
		g_mapping[frame->id()] += s.str();
		if(g_dumpKf && !g_dumpDir.empty()) dumpState(map->currentDepthMap, path6("kfnew", frame->id(), ".bin"));
		break;
	}
	}
}

std::vector<std::string> listImages(const std::string& source)
{
	std::vector<std::string> files;
	if(DIR* dp = opendir(source.c_str()))
	{
		while(dirent* e = readdir(dp))
		{
			std::string name = e->d_name;
			if(name != "." && name != "..") files.push_back(source + "/" + name);
		}
		closedir(dp);
		std::sort(files.begin(), files.end());
		return files;
	}
	std::ifstream f(source);
	if(!f) { fprintf(stderr, "lsd_oracle: cannot read %s\n", source.c_str()); exit(2); }
	std::string prefix = source.find('/') == std::string::npos ? "" : source.substr(0, source.rfind('/') + 1);
	std::string line;
	while(std::getline(f, line))
	{
		line.erase(0, line.find_first_not_of(" \t\r"));
		line.erase(line.find_last_not_of(" \t\r") + 1);
		if(line.empty() || line[0] == '#') continue;
		files.push_back(line[0] == '/' ? line : prefix + line);
	}
	return files;
}

void writePose(std::ostream& f, double t, const Sim3& S)
{
	Eigen::Quaterniond q(S.quaternion());
	q.normalize();
	Eigen::Vector3d p = S.translation();
	f << t << " " << p[0] << " " << p[1] << " " << p[2] << " " << q.x() << " " << q.y() << " " << q.z() << " "
	  << q.w() << "\n";
}
}  // namespace

int main(int argc, char** argv)
{
	Args a;
	for(int i = 1; i < argc; i++)
	{
		std::string s = argv[i];
		size_t eq = s.find('=');
		if(eq == std::string::npos) { fprintf(stderr, "lsd_oracle: expected key=value, got %s\n", argv[i]); return 2; }
		a.kv[s.substr(0, eq)] = s.substr(eq + 1);
	}
	if(!a.has("files") || !a.has("calib") || !a.has("out"))
	{
		fprintf(stderr, "usage: lsd_oracle files=LIST|DIR calib=FILE out=PREFIX [slam=0] [mt=0] [end=N] [seed=S] "
		                "[initdepth=F] [dumpinit=F] [dump=DIR dumpframes=A:B dumpkf=0|1] [affine=0] [kfusage=4] "
		                "[kfdist=3] [mingrad=5] [noise=4] [trace=1]\n");
		return 2;
	}
	// ROS start-up values (cfg/LSDParams.cfg), not settings.cpp's
	doSlam = std::stoi(a.get("slam", "0")) != 0;
	multiThreading = std::stoi(a.get("mt", "0")) != 0;
	useAffineLightningEstimation = std::stoi(a.get("affine", "0")) != 0;
	KFUsageWeight = std::stof(a.get("kfusage", "4"));
	KFDistWeight = std::stof(a.get("kfdist", "3"));
	minUseGrad = std::stof(a.get("mingrad", "5"));
	float noise = std::stof(a.get("noise", "4"));
	cameraPixelNoise2 = noise * noise;
	displayDepthMap = false;
	onSceenInfoDisplay = false;
	g_dumpDir = a.get("dump");
	g_dumpKf = std::stoi(a.get("dumpkf", "0")) != 0;
	if(a.has("dumpframes"))
	{
		std::string r = a.get("dumpframes");
		size_t c = r.find(':');
		g_dumpFirst = std::stoi(r.substr(0, c));
		g_dumpLast = c == std::string::npos ? g_dumpFirst : std::stoi(r.substr(c + 1));
	}

	Undistorter* undistorter = Undistorter::getUndistorterForFile(a.get("calib").c_str());
	if(!undistorter || !undistorter->isValid()) { fprintf(stderr, "lsd_oracle: bad calibration file\n"); return 2; }
	int w = undistorter->getOutputWidth(), h = undistorter->getOutputHeight();
	g_width = w;
	g_height = h;
	const cv::Mat& Kcv = undistorter->getK();  // stored transposed by LSD-SLAM
	Eigen::Matrix3f K;
	K << Kcv.at<double>(0, 0), 0, Kcv.at<double>(2, 0), 0, Kcv.at<double>(1, 1), Kcv.at<double>(2, 1), 0, 0, 1;
	printf("lsd_oracle: %dx%d, K = %g %g %g %g, slam=%d mt=%d affine=%d KFUsageWeight=%g KFDistWeight=%g\n", w, h,
	       K(0, 0), K(1, 1), K(0, 2), K(1, 2), (int)doSlam, (int)multiThreading, (int)useAffineLightningEstimation,
	       KFUsageWeight, KFDistWeight);

	std::vector<std::string> files = listImages(a.get("files"));
	int end = a.has("end") ? std::min<int>(std::stoi(a.get("end")), files.size()) : files.size();
	std::vector<float> initDepth;
	if(a.has("initdepth"))
	{
		initDepth.resize((size_t)w * h);
		FILE* f = fopen(a.get("initdepth").c_str(), "rb");
		if(!f || fread(initDepth.data(), sizeof(float), initDepth.size(), f) != initDepth.size())
		{
			fprintf(stderr, "lsd_oracle: %s is not %dx%d float32\n", a.get("initdepth").c_str(), w, h);
			return 2;
		}
		fclose(f);
	}

	// trace=0: no hook and no trace file (a speed measurement: the hooks' statistics cost time)
	bool tracing = std::stoi(a.get("trace", "1")) != 0;
	if(tracing) lsd_oracle_hook = hook;
	SlamSystem* system = new SlamSystem(w, h, K, doSlam);
	g_system = system;
	std::map<int, std::string> tracks;  // per frame: the tracking part of its trace line
	cv::Mat image(h, w, CV_8U);
	int idx = 0;
	float fakeTimeStamp = 0;
	for(int i = 0; i < end; i++)
	{
		cv::Mat dist = cv::imread(files[i], cv::IMREAD_GRAYSCALE);
		if(dist.rows != undistorter->getInputHeight() || dist.cols != undistorter->getInputWidth())
		{
			fprintf(stderr, "lsd_oracle: skipping %s (unreadable or wrong size)\n", files[i].c_str());
			continue;
		}
		undistorter->undistort(dist, image);
		{
			std::lock_guard<std::mutex> lock(g_mutex);
			g_rec = FrameRecord();
		}
		if(idx == 0)
		{
			if(a.has("seed")) srand(std::stoi(a.get("seed")));
			system->randomInit(image.data, fakeTimeStamp, idx);
			DepthMapPixelHypothesis* dm = system->map->currentDepthMap;
			if(!initDepth.empty())
			{
				for(int p = 0; p < w * h; p++)
				{
					float d = initDepth[p];
					if(std::isfinite(d) && d > 0)
						dm[p] = DepthMapPixelHypothesis(d, d, VAR_RANDOM_INIT_INITIAL, VAR_RANDOM_INIT_INITIAL, 20);
					else
					{
						dm[p].isValid = false;
						dm[p].blacklisted = 0;
					}
				}
				system->currentKeyFrame->setDepth(dm);
			}
			if(a.has("dumpinit"))
			{
				std::vector<float> out((size_t)w * h);
				for(int p = 0; p < w * h; p++) out[p] = dm[p].isValid ? dm[p].idepth : -1.f;
				FILE* f = fopen(a.get("dumpinit").c_str(), "wb");
				fwrite(out.data(), sizeof(float), out.size(), f);
				fclose(f);
			}
			tracks[0] = "{\"frame\": 0, \"keyframe\": true, \"init\": " + depthStats(dm);
		}
		else
		{
			if(inDumpRange(idx))
			{
				// the tracker's initial estimate, as SlamSystem::trackFrame computes it (keyframe -> frame)
				Sim3 init = system->currentKeyFrame->pose->getCamToWorld().inverse() *
				            system->keyFrameGraph->allFramePoses.back()->getCamToWorld();
				writeMatrix(path6("trackinit", idx, ".txt"), init.inverse(), 0);
			}
			system->trackFrame(image.data, idx, true, fakeTimeStamp);
			if(!tracing)
			{
				if(!system->trackingIsGood)
				{
					fprintf(stderr, "lsd_oracle: tracking lost at frame %d\n", idx);
					break;
				}
				idx++;
				fakeTimeStamp += 0.03;
				continue;
			}
			std::lock_guard<std::mutex> lock(g_mutex);
			bool isKf = system->currentKeyFrame->id() == idx;
			std::ostringstream trace;
			trace.precision(9);
			trace << "{\"frame\": " << idx << ", \"parent\": " << g_rec.parent << ", \"keyframe\": "
			      << (isKf ? "true" : "false") << ", \"lost\": " << (system->trackingIsGood ? "false" : "true")
			      << ", \"diverged\": " << (g_rec.diverged ? "true" : "false")
			      << ", \"tracking_good\": " << (g_rec.trackingGood ? "true" : "false")
			      << ", \"residual\": " << g_rec.residual << ", \"itr\": " << g_rec.itr
			      << ", \"usage\": " << g_rec.usage << ", \"good\": " << g_rec.good << ", \"bad\": " << g_rec.bad
			      << ", \"parent_mapped\": " << g_rec.parentMapped
			      << ", \"parent_mean_idepth\": " << g_rec.parentMeanIdepth << ", \"T_fk\": [";
			for(int k = 0; k < 12; k++) trace << g_rec.Tfk[k] << (k < 11 ? ", " : "]");
			tracks[idx] = trace.str();
			if(!system->trackingIsGood)
			{
				fprintf(stderr, "lsd_oracle: tracking lost at frame %d\n", idx);
				break;
			}
		}
		idx++;
		fakeTimeStamp += 0.03;
	}
	if(tracing)
	{
		usleep(300000);  // let the mapping thread finish the last frame (it overlaps the driver's loop)
		std::lock_guard<std::mutex> lock(g_mutex);
		std::ofstream trace(a.get("out") + "_trace.jsonl");
		for(auto& kv : tracks) trace << kv.second << g_mapping[kv.first] << "}\n";
	}

	// every frame's pose, and the keyframes. In SLAM mode after upstream's finalize() (final constraint search,
	// final optimisation, result merged by the mapping thread): a keyframe in the graph returns its optimised pose,
	// every other frame its tracking parent's (optimised) pose composed with its tracked frame->keyframe pose
	// (FramePoseStruct::getCamToWorld; merging invalidates the cached poses)
	if(doSlam) system->finalize();
	boost::shared_lock<boost::shared_mutex> poseLock(system->poseConsistencyMutex);  // no merge while writing
	std::ofstream traj(a.get("out") + ".txt"), kfs(a.get("out") + "_kf.txt");
	traj.precision(12);
	kfs.precision(12);
	std::vector<bool> isParent;
	for(FramePoseStruct* p : system->keyFrameGraph->allFramePoses)
		if(p->trackingParent)
		{
			if((int)isParent.size() <= p->trackingParent->frameID) isParent.resize(p->trackingParent->frameID + 1);
			isParent[p->trackingParent->frameID] = true;
		}
	for(FramePoseStruct* p : system->keyFrameGraph->allFramePoses)
	{
		Sim3 S = p->getCamToWorld();
		writePose(traj, p->frameID, S);
		if(p->frameID == 0 || (p->frameID < (int)isParent.size() && isParent[p->frameID])) writePose(kfs, p->frameID, S);
	}
	traj.close();
	kfs.close();
	if(doSlam)
	{
		// the pose graph's constraints: PREFIX_graph.txt, one line per keyframe pair (upstream inserts both
		// directions of an accepted reciprocal test): frame ids of the two keyframes and whether the pair is a
		// keyframe and the keyframe it was tracked on (the odometry edge; every other pair is a loop constraint
		// found by the constraint search)
		KeyFrameGraph* g = system->keyFrameGraph;
		std::map<std::pair<int, int>, bool> pairs;
		for(KFConstraintStruct* e : g->edgesAll)
		{
			int i = e->firstFrame->id(), j = e->secondFrame->id();
			bool odo = (e->firstFrame->hasTrackingParent() && e->firstFrame->getTrackingParent() == e->secondFrame) ||
			           (e->secondFrame->hasTrackingParent() && e->secondFrame->getTrackingParent() == e->firstFrame);
			pairs[std::make_pair(std::min(i, j), std::max(i, j))] = odo;
		}
		std::ofstream gf(a.get("out") + "_graph.txt");
		gf << "# keyframe_frame_a keyframe_frame_b odometry (1: a keyframe and its tracking parent, 0: loop)\n";
		int loops = 0;
		for(auto& kv : pairs)
		{
			gf << kv.first.first << " " << kv.first.second << " " << (kv.second ? 1 : 0) << "\n";
			loops += kv.second ? 0 : 1;
		}
		printf("lsd_oracle: graph: %d keyframes, %d constraints (%d keyframe pairs, %d loop)\n",
		       (int)g->keyframesAll.size(), (int)g->edgesAll.size(), (int)pairs.size(), loops);
	}
	printf("lsd_oracle: %d frames, wrote %s.txt\n", idx, a.get("out").c_str());
	fflush(stdout);
	_exit(0);  // skip the destructors: the threads are idle and the outputs are written
}
