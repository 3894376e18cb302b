#!/usr/bin/python3
"""Soak monitor (scripts/soak runs it): counts the frames the bag publishes (camera_info, one per frame), prints
the nodelet manager's resident memory every --every frames with the refiner's own counts (diagnostics), and
after --frames frames a summary: RSS after warm-up, at the end, its peak, and the growth. Exit 1 when the RSS grew
by more than --max-growth-mb after warm-up, or when the refiner stopped refining (no refined frame in the last
interval), or the manager died."""
import argparse
import sys
import threading
import time

import rospy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import CameraInfo
from diffdope_ros.msg import RefinedPoseArray


def rss_mb(pid, key="VmRSS"):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError("no %s for pid %d" % (key, pid))


class Counts:
    def __init__(self):
        self.lock = threading.Lock()
        self.frames = 0
        self.refined = 0
        self.diag = {}

    def on_info(self, _msg):
        with self.lock:
            self.frames += 1

    def on_refined(self, _msg):
        with self.lock:
            self.refined += 1

    def on_diagnostics(self, msg):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "frames refined" in values:
                with self.lock:
                    self.diag = values


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--pid", type=int, required=True, help="the nodelet manager's process id")
    ap.add_argument("--frames", type=int, default=10000)
    ap.add_argument("--every", type=int, default=1000)
    ap.add_argument("--warmup", type=int, default=1000, help="frames before the baseline RSS")
    ap.add_argument("--max-growth-mb", type=float, default=64.0)
    ap.add_argument("--info-topic", default="/camera/rgb/camera_info")
    ap.add_argument("--refiner", default="/diffdope_refiner")
    args = ap.parse_args(rospy.myargv()[1:])

    rospy.init_node("soak_monitor", disable_signals=True)
    c = Counts()
    rospy.Subscriber(args.info_topic, CameraInfo, c.on_info, queue_size=100)
    rospy.Subscriber(args.refiner + "/refined_poses", RefinedPoseArray, c.on_refined, queue_size=100)
    rospy.Subscriber("/diagnostics", DiagnosticArray, c.on_diagnostics, queue_size=10)

    start = time.time()
    next_report, baseline, samples, last_refined = args.every, None, [], 0
    print("%8s %8s %8s %9s %9s  %s" % ("frames", "refined", "wall s", "RSS MB", "peak MB", "refiner diagnostics"))
    sys.stdout.flush()
    while True:
        time.sleep(0.2)
        try:
            rss, peak = rss_mb(args.pid), rss_mb(args.pid, "VmHWM")
        except (OSError, RuntimeError) as e:
            print("soak: the nodelet manager (pid %d) is gone: %s" % (args.pid, e))
            return 1
        with c.lock:
            frames, refined, diag = c.frames, c.refined, dict(c.diag)
        if frames < next_report:
            if time.time() - start > 20 and frames == 0:
                print("soak: no frame on %s after 20 s (is the bag playing?)" % args.info_topic)
                return 1
            continue
        samples.append((frames, rss))
        print("%8d %8d %8.0f %9.1f %9.1f  synchronized %s, refined %s, skipped %s, errors: %s" % (
            frames, refined, time.time() - start, rss, peak, diag.get("frames synchronized", "?"),
            diag.get("frames refined", "?"), diag.get("frames skipped (worker busy)", "?"),
            diag.get("last error", "") or "none"))
        sys.stdout.flush()
        if refined == last_refined:
            print("soak: no refined frame in the last %d frames" % args.every)
            return 1
        last_refined = refined
        next_report += args.every
        if frames >= args.frames:
            break
    warm = [(f, r) for f, r in samples if f >= args.warmup] or samples[-1:]
    (warm_frames, baseline), final = warm[0], samples[-1][1]
    after = [r for _, r in warm]
    growth = final - baseline
    print("soak summary: %d frames (%d refined) in %.0f s; manager RSS %.1f MB after %d frames of warm-up, %.1f MB "
          "at the end (growth %+.1f MB; range after warm-up %.1f-%.1f MB), peak %.1f MB" % (
              frames, refined, time.time() - start, baseline, warm_frames, final, growth, min(after), max(after),
              rss_mb(args.pid, "VmHWM")))
    if growth > args.max_growth_mb:
        print("soak: FAILED, the RSS grew by %.1f MB after warm-up (limit %.1f MB)" % (growth, args.max_growth_mb))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
