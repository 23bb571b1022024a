// Shape classes, posing and rigid placement for synth.h. The polygonizer is
// in polygonize.cc.
//
// Coordinates: y up, z forward, x to the creature's left; shapes are about
// one to two units tall. Each class is built by a small function from a few
// proportions, so "similar-skeleton" pairs (Tam & Lau 2007, section 1: the
// hard case for topology-only methods) share code and differ only in
// numbers.
#include "extractor/synth/synth.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace tpr::synth {
namespace {

using Eigen::AngleAxisd;
using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kDeg = M_PI / 180.0;

// A bone in the rest pose plus its joint limit: the largest swing (radians)
// about an axis perpendicular to the bone, at its start.
struct TemplateBone {
  Bone bone;
  double limit = 0.0;
  // Hinge joints (fingers) swing about this rest-frame axis only, through
  // [-limit / 3, limit]; a zero axis means a ball joint.
  Vector3d hinge = Vector3d::Zero();
};

class Builder {
 public:
  // Adds a bone from `start` to `end`; returns its index.
  int Add(const std::string& name, int parent, const Vector3d& start,
          const Vector3d& end, double r0, double r1, double limit_deg) {
    TemplateBone t;
    t.bone.parent = parent;
    t.bone.start = start;
    t.bone.end = end;
    t.bone.start_radius = r0;
    t.bone.end_radius = r1;
    t.bone.name = name;
    t.limit = limit_deg * kDeg;
    bones_.push_back(t);
    return static_cast<int>(bones_.size()) - 1;
  }
  // Adds a chain through `points` (first is the start) with radii tapering
  // linearly from r0 to r1; returns the index of the last bone.
  int Chain(const std::string& name, int parent,
            const std::vector<Vector3d>& points, double r0, double r1,
            double limit_deg) {
    const int n = static_cast<int>(points.size()) - 1;
    for (int i = 0; i < n; ++i) {
      const double a = r0 + (r1 - r0) * i / n;
      const double b = r0 + (r1 - r0) * (i + 1) / n;
      parent = Add(absl::StrCat(name, i), parent, points[i], points[i + 1], a,
                   b, limit_deg);
    }
    return parent;
  }
  // Makes bones [first, last] hinges about `axis`.
  void Hinge(int first, int last, const Vector3d& axis) {
    for (int i = first; i <= last; ++i) bones_[i].hinge = axis.normalized();
  }
  int size() const { return static_cast<int>(bones_.size()); }
  const std::vector<TemplateBone>& bones() const { return bones_; }

 private:
  std::vector<TemplateBone> bones_;
};

Vector3d V(double x, double y, double z) { return Vector3d(x, y, z); }

// Adult and child share this; the child has a bigger head, shorter limbs and
// a relatively thicker body.
struct BipedProportions {
  double height;  // top of the pelvis bone
  double torso_r;
  double head_r;
  double arm_len;  // upper arm; forearm is 0.9 of it
  double arm_r;
  double leg_len;  // thigh; shin is 0.95 of it
  double leg_r;
};

std::vector<TemplateBone> Biped(const BipedProportions& p) {
  Builder b;
  const double hip_y = p.leg_len * 1.95 + 0.08;
  const int pelvis =
      b.Add("pelvis", -1, V(0, hip_y, 0), V(0, hip_y + 0.6 * p.torso_r, 0),
            p.torso_r * 0.95, p.torso_r, 0);
  const double chest_y = hip_y + 0.6 * p.torso_r + p.height;
  const int chest = b.Add("chest", pelvis, V(0, hip_y + 0.6 * p.torso_r, 0),
                          V(0, chest_y, 0), p.torso_r, p.torso_r * 1.05, 15);
  const int neck =
      b.Add("neck", chest, V(0, chest_y, 0), V(0, chest_y + p.torso_r * 0.8, 0),
            p.arm_r, p.arm_r, 20);
  b.Add("head", neck, V(0, chest_y + p.torso_r * 0.8 + p.head_r * 0.6, 0),
        V(0, chest_y + p.torso_r * 0.8 + p.head_r * 1.0, 0), p.head_r,
        p.head_r * 0.95, 20);
  for (int side : {-1, 1}) {
    const std::string s = side < 0 ? "r_" : "l_";
    const double sx = side * (p.torso_r + p.arm_r * 1.2);
    const double sy = chest_y - p.arm_r;
    const int clav = b.Add(s + "clavicle", chest, V(0, sy, 0), V(sx, sy, 0),
                           p.arm_r * 1.1, p.arm_r * 1.1, 5);
    // A-pose: arms 40 degrees out from the body, so they stay clear of it.
    const Vector3d dir = V(side * std::sin(40 * kDeg), -std::cos(40 * kDeg), 0);
    const Vector3d elbow = V(sx, sy, 0) + p.arm_len * dir;
    const Vector3d wrist = elbow + 0.9 * p.arm_len * dir;
    const int upper = b.Add(s + "upper_arm", clav, V(sx, sy, 0), elbow,
                            p.arm_r * 1.1, p.arm_r, 45);
    const int fore =
        b.Add(s + "forearm", upper, elbow, wrist, p.arm_r, p.arm_r * 0.85, 55);
    b.Add(s + "hand", fore, wrist, wrist + 0.35 * p.arm_len * dir,
          p.arm_r * 0.9, p.arm_r * 0.8, 30);
    const double hx = side * (p.leg_r + 0.35 * p.torso_r);
    const Vector3d hip = V(hx, hip_y, 0);
    const Vector3d knee = V(hx * 1.15, hip_y - p.leg_len, 0);
    const Vector3d ankle = V(hx * 1.2, hip_y - 1.95 * p.leg_len, 0);
    const int thigh =
        b.Add(s + "thigh", pelvis, hip, knee, p.leg_r, p.leg_r * 0.8, 35);
    const int shin = b.Add(s + "shin", thigh, knee, ankle, p.leg_r * 0.75,
                           p.leg_r * 0.6, 45);
    b.Add(s + "foot", shin, ankle, ankle + V(0, -0.03, 0.45 * p.leg_len),
          p.leg_r * 0.6, p.leg_r * 0.5, 20);
  }
  return b.bones();
}

// The adult biped's proportions: "biped_adult", and the body identity
// mode scales.
constexpr BipedProportions kAdult = {0.55, 0.15, 0.11, 0.3, 0.045, 0.45, 0.075};

struct QuadrupedProportions {
  double body_r;
  double body_len;
  double leg_len;  // each of the two leg segments
  double leg_r;
  double neck_r;
  double tail_r;
};

std::vector<TemplateBone> Quadruped(const QuadrupedProportions& p) {
  Builder b;
  const double y = 2.0 * p.leg_len + 0.6 * p.body_r;
  const double zb = -0.5 * p.body_len, zf = 0.5 * p.body_len;
  const int body = b.Add("body", -1, V(0, y, zb), V(0, y + 0.05, zf), p.body_r,
                         p.body_r * 1.05, 0);
  const Vector3d head_base = V(0, y + 0.35, zf + 0.3);
  const int neck = b.Add("neck", body, V(0, y + 0.05, zf), head_base, p.neck_r,
                         p.neck_r * 0.9, 20);
  b.Add("head", neck, head_base, head_base + V(0, -0.05, 0.28), p.neck_r * 1.3,
        p.neck_r * 0.8, 20);
  b.Chain("tail", body,
          {V(0, y, zb), V(0, y - 0.1, zb - 0.3), V(0, y - 0.25, zb - 0.55)},
          p.tail_r, p.tail_r * 0.7, 30);
  for (int front : {0, 1}) {
    for (int side : {-1, 1}) {
      const std::string s =
          absl::StrCat(front ? "f" : "b", side < 0 ? "r_" : "l_");
      const double z = front ? zf - 0.1 : zb + 0.1;
      const double x = side * (p.body_r * 0.55 + p.leg_r * 0.4);
      const Vector3d hip = V(x, y - 0.4 * p.body_r, z);
      const Vector3d knee = V(x * 1.1, y - 0.4 * p.body_r - p.leg_len, z);
      const Vector3d foot = V(x * 1.1, 0.0, z + 0.05);
      const int upper =
          b.Add(s + "upper_leg", body, hip, knee, p.leg_r, p.leg_r * 0.85, 30);
      b.Add(s + "lower_leg", upper, knee, foot, p.leg_r * 0.8, p.leg_r * 0.65,
            40);
    }
  }
  return b.bones();
}

std::vector<TemplateBone> Octopus() {
  Builder b;
  // The mantle sits well above the arms so that arms may curl up.
  const int head =
      b.Add("mantle", -1, V(0, 0.5, 0), V(0, 0.75, 0), 0.3, 0.27, 0);
  for (int i = 0; i < 8; ++i) {
    const double a = 2.0 * M_PI * (i + 0.5) / 8.0;
    const Vector3d out = V(std::cos(a), 0, std::sin(a));
    const int root = b.Add(absl::StrCat("arm", i, "_root"), head, V(0, 0.4, 0),
                           V(0, 0.1, 0) + 0.35 * out, 0.09, 0.085, 5);
    std::vector<Vector3d> pts;
    for (int k = 0; k <= 3; ++k) {
      pts.push_back(V(0, 0.1 - 0.05 * k, 0) + (0.35 + 0.27 * k) * out);
    }
    b.Chain(absl::StrCat("arm", i, "_"), root, pts, 0.08, 0.04, 20);
  }
  return b.bones();
}

std::vector<TemplateBone> Hand() {
  Builder b;
  const int palm =
      b.Add("palm", -1, V(0, 0.0, 0), V(0, 0.32, 0), 0.16, 0.16, 0);
  const double fan[4] = {-21, -7, 7, 21};
  const double lengths[4] = {0.3, 0.36, 0.34, 0.27};
  for (int f = 0; f < 4; ++f) {
    const double a = fan[f] * kDeg;
    const Vector3d dir = V(std::sin(a), std::cos(a), 0);
    const Vector3d knuckle = V(0.19 * (f - 1.5) / 1.5, 0.42, 0);
    const int meta =
        b.Add(absl::StrCat("meta", f), palm, V(knuckle.x() * 0.4, 0.25, 0),
              knuckle, 0.05, 0.045, 3);
    const int first = b.size();
    const int last =
        b.Chain(absl::StrCat("finger", f, "_"), meta,
                {knuckle, knuckle + 0.42 * lengths[f] * dir,
                 knuckle + 0.74 * lengths[f] * dir, knuckle + lengths[f] * dir},
                0.042, 0.03, 40);
    // Fingers curl towards the palm's front (+z).
    b.Hinge(first, last, dir.cross(V(0, 0, 1)));
  }
  const Vector3d thumb_dir = V(-0.8, 0.6, 0.25).normalized();
  const Vector3d thumb_base = V(-0.17, 0.12, 0.03);
  const int tmeta =
      b.Add("thumb_meta", palm, V(-0.05, 0.08, 0), thumb_base, 0.055, 0.05, 5);
  const int first = b.size();
  const int last = b.Chain("thumb", tmeta,
                           {thumb_base, thumb_base + 0.15 * thumb_dir,
                            thumb_base + 0.27 * thumb_dir},
                           0.048, 0.035, 35);
  b.Hinge(first, last, thumb_dir.cross(V(0, 0, 1)));
  return b.bones();
}

std::vector<TemplateBone> Ant() {
  Builder b;
  const int thorax =
      b.Add("thorax", -1, V(0, 0.35, 0.08), V(0, 0.37, 0.38), 0.09, 0.08, 0);
  const int neck = b.Add("neck", thorax, V(0, 0.37, 0.38), V(0, 0.42, 0.5),
                         0.045, 0.045, 15);
  const int head =
      b.Add("head", neck, V(0, 0.44, 0.56), V(0, 0.44, 0.6), 0.1, 0.09, 15);
  for (int side : {-1, 1}) {
    const Vector3d base = V(side * 0.05, 0.5, 0.62);
    b.Chain(side < 0 ? "r_antenna" : "l_antenna", head,
            {base, base + V(side * 0.12, 0.18, 0.08),
             base + V(side * 0.2, 0.22, 0.3)},
            0.028, 0.022, 20);
  }
  const int petiole = b.Add("petiole", thorax, V(0, 0.35, 0.08),
                            V(0, 0.36, -0.1), 0.05, 0.05, 15);
  b.Add("gaster", petiole, V(0, 0.38, -0.22), V(0, 0.42, -0.5), 0.16, 0.12, 10);
  const double zs[3] = {0.32, 0.22, 0.12};
  const double sweep[3] = {40, 0, -40};
  for (int l = 0; l < 3; ++l) {
    for (int side : {-1, 1}) {
      const std::string s = absl::StrCat(side < 0 ? "r" : "l", "_leg", l, "_");
      const double a = sweep[l] * kDeg;
      const Vector3d out = V(side * std::cos(a), 0, std::sin(a));
      const Vector3d hip = V(0, 0.33, zs[l]) + 0.1 * out;
      const int coxa =
          b.Add(s + "coxa", thorax, V(0, 0.33, zs[l]), hip, 0.04, 0.036, 5);
      const Vector3d knee = hip + 0.25 * out + V(0, 0.14, 0);
      const Vector3d foot = knee + 0.25 * out + V(0, -0.5, 0);
      const int femur = b.Add(s + "femur", coxa, hip, knee, 0.034, 0.03, 20);
      b.Add(s + "tibia", femur, knee, foot, 0.028, 0.022, 25);
    }
  }
  return b.bones();
}

std::vector<TemplateBone> Bird() {
  Builder b;
  const int body =
      b.Add("body", -1, V(0, 0.5, -0.22), V(0, 0.56, 0.18), 0.15, 0.16, 0);
  const int neck =
      b.Add("neck", body, V(0, 0.58, 0.2), V(0, 0.76, 0.3), 0.06, 0.055, 20);
  const int head =
      b.Add("head", neck, V(0, 0.8, 0.32), V(0, 0.81, 0.38), 0.08, 0.075, 20);
  b.Add("beak", head, V(0, 0.8, 0.42), V(0, 0.77, 0.6), 0.04, 0.025, 10);
  b.Chain("tail", body, {V(0, 0.5, -0.3), V(0, 0.46, -0.5), V(0, 0.44, -0.66)},
          0.06, 0.035, 15);
  for (int side : {-1, 1}) {
    const std::string s = side < 0 ? "r_" : "l_";
    b.Chain(s + "wing", body,
            {V(side * 0.08, 0.6, 0.05), V(side * 0.45, 0.68, 0.0),
             V(side * 0.8, 0.62, -0.08), V(side * 1.05, 0.58, -0.15)},
            0.055, 0.03, 25);
    const int leg = b.Add(s + "leg", body, V(side * 0.07, 0.42, 0.0),
                          V(side * 0.09, 0.15, 0.02), 0.035, 0.028, 20);
    b.Add(s + "foot", leg, V(side * 0.09, 0.15, 0.02),
          V(side * 0.09, 0.1, 0.15), 0.028, 0.025, 15);
  }
  return b.bones();
}

std::vector<TemplateBone> Snake() {
  Builder b;
  const int head =
      b.Add("head", -1, V(0, 0.1, 0.05), V(0, 0.1, 0.2), 0.09, 0.075, 0);
  std::vector<Vector3d> pts;
  for (int k = 0; k <= 9; ++k) pts.push_back(V(0, 0.1, 0.05 - 0.22 * k));
  b.Chain("body", head, pts, 0.075, 0.03, 22);
  return b.bones();
}

std::vector<TemplateBone> Pliers() {
  Builder b;
  const int pivot = b.Add("pivot", -1, V(0, 0, 0), V(0, 0, 0), 0.085, 0.085, 0);
  for (int side : {-1, 1}) {
    const std::string s = side < 0 ? "r_" : "l_";
    b.Add(s + "jaw", pivot, V(0, 0, 0), V(side * 0.07, 0.55, 0), 0.05, 0.026,
          10);
    b.Chain(s + "handle", pivot,
            {V(0, 0, 0), V(side * 0.1, -0.4, 0), V(side * 0.2, -0.85, 0)}, 0.05,
            0.04, 10);
  }
  return b.bones();
}

struct ShapeClass {
  const char* name;
  std::function<std::vector<TemplateBone>()> build;
};

const std::vector<ShapeClass>& Classes() {
  static const auto* classes = new std::vector<ShapeClass>{
      {"biped_adult", [] { return Biped(kAdult); }},
      {"biped_child",
       [] {
         return Biped({0.33, 0.13, 0.15, 0.18, 0.045, 0.27, 0.07});
       }},
      {"quadruped_slender",
       [] {
         return Quadruped({0.16, 0.8, 0.33, 0.055, 0.07, 0.045});
       }},
      {"quadruped_stocky",
       [] {
         return Quadruped({0.24, 0.8, 0.25, 0.09, 0.11, 0.06});
       }},
      {"octopus", Octopus},
      {"hand", Hand},
      {"ant", Ant},
      {"bird", Bird},
      {"snake", Snake},
      {"pliers", Pliers},
  };
  return *classes;
}

// SplitMix64: tiny, portable and fully specified, unlike the distributions of
// <random>, whose output may differ between standard libraries.
class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }

 private:
  uint64_t state_;
};

uint64_t Mix(uint64_t a, uint64_t b) {
  Rng r(a * 0x2545F4914F6CDD1Dull ^ b);
  return r.Next();
}

uint64_t StreamSeed(uint64_t seed, uint64_t shape_id, uint64_t pose,
                    uint64_t purpose) {
  return Mix(Mix(Mix(seed, shape_id), pose), purpose);
}

// Surface gap between bone i's sample point s (0..1) and bone j's capsule.
double SampleGap(const Bone& bi, double s, const Bone& bj) {
  const Vector3d p = bi.start + s * (bi.end - bi.start);
  const double ri = bi.start_radius + s * (bi.end_radius - bi.start_radius);
  const Vector3d ab = bj.end - bj.start;
  const double len2 = ab.squaredNorm();
  double t = len2 > 0.0 ? (p - bj.start).dot(ab) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double rj = bj.start_radius + t * (bj.end_radius - bj.start_radius);
  return (p - (bj.start + t * ab)).norm() - ri - rj;
}

constexpr int kGapSamples = 9;

// Limbs must not come closer than this; with the polygonizer's blend radius
// of half the thinnest radius, this keeps several grid cells between them.
double GapThreshold(const std::vector<TemplateBone>& bones) {
  double r_min = 1e300;
  for (const auto& t : bones) {
    r_min = std::min({r_min, t.bone.start_radius, t.bone.end_radius});
  }
  return 2.0 * r_min;
}

// True when bone i (posed) keeps the threshold gap to every earlier bone j
// other than its parent, in both directions, at every sample that had it at
// rest. Samples closer than that at rest lie next to a shared joint
// (siblings, the torso beside a limb's root), where the surface blends
// anyway and rotation about that joint barely moves them.
bool SeparatedFromEarlier(const std::vector<TemplateBone>& rest,
                          const std::vector<Bone>& posed, size_t i,
                          double threshold) {
  for (size_t j = 0; j < i; ++j) {
    if (rest[i].bone.parent == static_cast<int>(j)) continue;
    for (int k = 0; k < kGapSamples; ++k) {
      const double s = static_cast<double>(k) / (kGapSamples - 1);
      if (SampleGap(rest[i].bone, s, rest[j].bone) >= threshold &&
          SampleGap(posed[i], s, posed[j]) < threshold) {
        return false;
      }
      if (SampleGap(rest[j].bone, s, rest[i].bone) >= threshold &&
          SampleGap(posed[j], s, posed[i]) < threshold) {
        return false;
      }
    }
  }
  return true;
}

// Forward kinematics with rejection, bone by bone (parents first): each bone
// swings about its start by a random angle up to limit * amount around a
// random axis perpendicular to it, and children ride on their parent's
// rigid motion. A swing that brings the bone too close to an earlier bone is
// redrawn, then shrunk, then dropped; redrawing one bone instead of the
// whole skeleton keeps poses varied for many-limbed classes. Returns false
// if even the unswung bone collides (a parent's pose left no room). On
// success `rot` holds each bone's rotation from rest: bone i maps rest point
// p to out[i].start + rot[i] (p - bones[i].bone.start).
bool Pose(const std::vector<TemplateBone>& bones, Rng& rng, double amount,
          double threshold, std::vector<Bone>* out,
          std::vector<Matrix3d>* rotations) {
  const size_t n = bones.size();
  std::vector<Matrix3d>& rot = *rotations;
  rot.assign(n, Matrix3d::Identity());
  out->assign(n, Bone());
  for (size_t i = 0; i < n; ++i) {
    const Bone& rest = bones[i].bone;
    const Vector3d rest_dir = rest.end - rest.start;
    const Matrix3d parent_rot =
        rest.parent < 0 ? Matrix3d::Identity() : rot[rest.parent];
    Bone& b = (*out)[i];
    b = rest;
    if (rest.parent >= 0) {
      const Bone& pr = bones[rest.parent].bone;
      b.start =
          (*out)[rest.parent].start + parent_rot * (rest.start - pr.start);
    }
    constexpr int kTries = 8;
    bool placed = false;
    for (int attempt = 0; attempt <= kTries && !placed; ++attempt) {
      Matrix3d local = Matrix3d::Identity();
      if (attempt < kTries) {
        // Random unit axis perpendicular to the bone (any axis for balls).
        Vector3d axis(rng.Uniform(-1, 1), rng.Uniform(-1, 1),
                      rng.Uniform(-1, 1));
        const double shrink = attempt < 4 ? 1.0 : std::pow(0.5, attempt - 3);
        double angle = rng.Uniform(-1, 1) * bones[i].limit * amount * shrink;
        if (bones[i].hinge.squaredNorm() > 0.0) {
          axis = bones[i].hinge;
          if (angle < 0.0) angle /= 3.0;
        } else if (rest_dir.squaredNorm() > 0.0) {
          const Vector3d d = rest_dir.normalized();
          axis -= d * d.dot(axis);
        }
        if (axis.norm() > 1e-6 && angle != 0.0) {
          local = AngleAxisd(angle, axis.normalized()).toRotationMatrix();
        }
      }
      rot[i] = parent_rot * local;
      b.end = b.start + rot[i] * rest_dir;
      placed = SeparatedFromEarlier(bones, *out, i, threshold);
    }
    if (!placed) return false;
  }
  return true;
}

absl::Status CheckOptions(const ShapeOptions& options, int pose_index) {
  if (pose_index < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("pose_index ", pose_index, " is negative"));
  }
  if (options.target_vertices < 200 || options.target_vertices > 1'000'000) {
    return absl::InvalidArgumentError(
        absl::StrCat("target_vertices ", options.target_vertices,
                     " is outside [200, 1000000]"));
  }
  if (!(options.pose_amount >= 0.0 && options.pose_amount <= 1.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "pose_amount ", options.pose_amount, " is outside [0, 1]"));
  }
  return absl::OkStatus();
}

struct Similarity {
  Matrix3d rotation = Matrix3d::Identity();
  Vector3d translation = Vector3d::Zero();
  double scale = 1.0;
  Vector3d Apply(const Vector3d& p) const {
    return scale * (rotation * p) + translation;
  }
};

Similarity DrawSimilarity(uint64_t seed) {
  Rng rng(seed);
  // Uniform random rotation from a uniform unit quaternion (Shoemake).
  const double u1 = rng.Uniform(), u2 = rng.Uniform(), u3 = rng.Uniform();
  const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
  const Eigen::Quaterniond q(
      a * std::sin(2 * M_PI * u2), a * std::cos(2 * M_PI * u2),
      b * std::sin(2 * M_PI * u3), b * std::cos(2 * M_PI * u3));
  Similarity s;
  s.rotation = q.normalized().toRotationMatrix();
  s.translation =
      Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
  s.scale = rng.Uniform(1.0, 2.0);
  return s;
}

// A posed skeleton in its own frame, and where to place it.
struct Posed {
  Skeleton skeleton;
  // Bone i's rotation from rest (Pose); identity for every bone at rest.
  std::vector<Matrix3d> rotations;
  Similarity placement;
};

Posed PoseTemplate(const std::vector<TemplateBone>& bones, uint64_t shape_id,
                   int pose_index, const ShapeOptions& options) {
  const double threshold = GapThreshold(bones);
  Posed posed;
  for (const auto& t : bones) posed.skeleton.bones.push_back(t.bone);
  posed.rotations.assign(bones.size(), Matrix3d::Identity());
  // A few full-range draws, then draws damped towards the rest pose, which
  // is the last resort and always separated.
  for (int attempt = 0; attempt < 36; ++attempt) {
    const double amount = options.pose_amount *
                          (attempt < 30 ? 1.0 : std::pow(0.7, attempt - 29));
    if (amount == 0.0) break;
    Rng rng(StreamSeed(options.seed, shape_id, pose_index, 1 + attempt));
    std::vector<Bone> candidate;
    std::vector<Matrix3d> rotations;
    if (Pose(bones, rng, amount, threshold, &candidate, &rotations)) {
      posed.skeleton.bones = std::move(candidate);
      posed.rotations = std::move(rotations);
      break;
    }
  }
  if (options.random_rigid) {
    posed.placement = DrawSimilarity(
        StreamSeed(options.seed, shape_id, pose_index, 0xC0FFEE));
  }
  return posed;
}

Skeleton Place(const Posed& posed) {
  Skeleton out = posed.skeleton;
  const Similarity& s = posed.placement;
  for (Bone& b : out.bones) {
    b.start = s.Apply(b.start);
    b.end = s.Apply(b.end);
    b.start_radius *= s.scale;
    b.end_radius *= s.scale;
  }
  return out;
}

absl::StatusOr<extract::Mesh> MeshOf(const Posed& posed, int target) {
  absl::StatusOr<extract::Mesh> mesh = MeshFromSkeleton(posed.skeleton, target);
  if (!mesh.ok()) return mesh.status();
  for (Eigen::Vector3d& p : mesh->positions) p = posed.placement.Apply(p);
  return mesh;
}

// A rigid motion p -> R p + t as a unit dual quaternion real + eps dual,
// dual = t real / 2 (t read as a pure quaternion), stored as 4-vectors
// (x, y, z, w) so that blending is plain vector arithmetic.
struct DualQuaternion {
  Eigen::Vector4d real;
  Eigen::Vector4d dual;
};

DualQuaternion ToDualQuaternion(const Matrix3d& rotation,
                                const Vector3d& translation) {
  const Eigen::Quaterniond r(rotation);
  const Eigen::Quaterniond t(0.0, translation.x(), translation.y(),
                             translation.z());
  const Eigen::Quaterniond d = t * r;
  return {r.coeffs(), 0.5 * d.coeffs()};
}

// Dual-quaternion linear blending (Kavan et al. 2008, DLB): the weighted sum
// of the bones' dual quaternions, each sign-aligned with the heaviest one
// (q and -q are one motion), normalized, applied to `p`.
Vector3d BlendMotions(const std::vector<BoneWeight>& weights,
                      const std::vector<DualQuaternion>& motions,
                      const Vector3d& p) {
  size_t heaviest = 0;
  for (size_t i = 1; i < weights.size(); ++i) {
    if (weights[i].weight > weights[heaviest].weight) heaviest = i;
  }
  const Eigen::Vector4d& pivot = motions[weights[heaviest].bone].real;
  Eigen::Vector4d real = Eigen::Vector4d::Zero(), dual = real;
  for (const BoneWeight& w : weights) {
    const DualQuaternion& m = motions[w.bone];
    const double sign = m.real.dot(pivot) < 0.0 ? -1.0 : 1.0;
    real += sign * w.weight * m.real;
    dual += sign * w.weight * m.dual;
  }
  const double norm = real.norm();
  const Eigen::Quaterniond r(real / norm), d(dual / norm);
  // Translation 2 d conj(r); its vector part is exact for a unit blend and
  // drops the component of d along r that normalization leaves otherwise.
  const Vector3d t = 2.0 * (d * r.conjugate()).vec();
  return r.toRotationMatrix() * p + t;
}

// Skin moves the rest mesh of `rest` (pose_amount 0) to `posed` by dual-
// quaternion skinning with SkinWeights (synth.h, identity mode).
extract::Mesh Skin(const Skeleton& rest, const Posed& posed,
                   extract::Mesh mesh) {
  std::vector<DualQuaternion> motions;
  for (size_t i = 0; i < rest.bones.size(); ++i) {
    const Matrix3d& r = posed.rotations[i];
    motions.push_back(ToDualQuaternion(
        r, posed.skeleton.bones[i].start - r * rest.bones[i].start));
  }
  // Blend over about a limb's radius (the mean bone radius) on either side
  // of a junction (synth.h, identity mode).
  double radius = 0.0;
  for (const Bone& b : rest.bones) {
    radius += 0.5 * (b.start_radius + b.end_radius);
  }
  const double blend_length = radius / rest.bones.size();
  const std::vector<std::vector<BoneWeight>> weights =
      SkinWeights(rest, mesh, blend_length);
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    mesh.positions[v] = posed.placement.Apply(
        BlendMotions(weights[v], motions, mesh.positions[v]));
  }
  return mesh;
}

absl::StatusOr<Posed> PoseClass(absl::string_view class_name, int pose_index,
                                const ShapeOptions& options) {
  absl::Status ok = CheckOptions(options, pose_index);
  if (!ok.ok()) return ok;
  const auto& classes = Classes();
  for (size_t i = 0; i < classes.size(); ++i) {
    if (class_name == classes[i].name) {
      return PoseTemplate(classes[i].build(), i, pose_index, options);
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat("unknown shape class '", class_name,
                   "'; valid: ", absl::StrJoin(ClassNames(), ", ")));
}

std::vector<TemplateBone> Star(int arms) {
  // Arm directions spread evenly: polygons for 2 and 3 arms, then the
  // tetrahedron, triangular bipyramid, octahedron, pentagonal bipyramid and
  // square antiprism.
  std::vector<Vector3d> dirs;
  auto ring = [&](int k, double y, double phase) {
    const double r = std::sqrt(1.0 - y * y);
    for (int i = 0; i < k; ++i) {
      const double a = 2.0 * M_PI * i / k + phase;
      dirs.push_back(V(r * std::cos(a), y, r * std::sin(a)));
    }
  };
  switch (arms) {
    case 2:
      ring(2, 0, 0);
      break;
    case 3:
      ring(3, 0, 0);
      break;
    case 4:
      dirs = {V(1, 1, 1), V(1, -1, -1), V(-1, 1, -1), V(-1, -1, 1)};
      break;
    case 5:
      ring(3, 0, 0);
      dirs.push_back(V(0, 1, 0));
      dirs.push_back(V(0, -1, 0));
      break;
    case 6:
      dirs = {V(1, 0, 0),  V(-1, 0, 0), V(0, 1, 0),
              V(0, -1, 0), V(0, 0, 1),  V(0, 0, -1)};
      break;
    case 7:
      ring(5, 0, 0);
      dirs.push_back(V(0, 1, 0));
      dirs.push_back(V(0, -1, 0));
      break;
    default:
      ring(4, 0.45, 0);
      ring(4, -0.45, M_PI / 4);
      break;
  }
  Builder b;
  const int ball = b.Add("ball", -1, V(0, 0, 0), V(0, 0, 0), 0.35, 0.35, 0);
  for (int i = 0; i < arms; ++i) {
    const Vector3d d = dirs[i].normalized();
    const int inner = b.Add(absl::StrCat("arm", i, "_inner"), ball, V(0, 0, 0),
                            0.6 * d, 0.1, 0.1, 5);
    b.Add(absl::StrCat("arm", i, "_outer"), inner, 0.6 * d, 1.2 * d, 0.1, 0.1,
          20);
  }
  return b.bones();
}

// Shape ids for the seed stream: classes use their index, stars 1000 +
// arms, identity bodies 2000 + body (posing) and 3000 (proportions).
constexpr uint64_t kStarIdBase = 1000;
constexpr uint64_t kIdentityIdBase = 2000;
constexpr uint64_t kIdentityProportionsId = 3000;

std::array<double, 7> Factors(const BodyProportions& b) {
  return {b.torso_length,  b.torso_thickness, b.head_size,    b.arm_length,
          b.arm_thickness, b.leg_length,      b.leg_thickness};
}

BodyProportions DrawBody(Rng& rng) {
  BodyProportions b;
  b.torso_length = rng.Uniform(0.8, 1.2);
  b.torso_thickness = rng.Uniform(0.8, 1.3);
  b.head_size = rng.Uniform(0.85, 1.15);
  b.arm_length = rng.Uniform(0.8, 1.2);
  b.arm_thickness = rng.Uniform(0.8, 1.3);
  b.leg_length = rng.Uniform(0.8, 1.2);
  b.leg_thickness = rng.Uniform(0.8, 1.3);
  return b;
}

// Bodies 0..body drawn in order, each redrawn until it is at least
// kMinApart (largest absolute log-factor) from every earlier one; after
// many failed draws the last draw is kept (only with hundreds of bodies).
std::vector<BodyProportions> DrawBodies(int count, uint64_t seed) {
  constexpr double kMinApart = 0.1;
  std::vector<BodyProportions> bodies;
  for (int i = 0; i < count; ++i) {
    Rng rng(
        StreamSeed(seed, kIdentityProportionsId, static_cast<uint64_t>(i), 0));
    BodyProportions b;
    for (int attempt = 0; attempt < 200; ++attempt) {
      b = DrawBody(rng);
      bool apart = true;
      for (const BodyProportions& other : bodies) {
        const std::array<double, 7> x = Factors(b), y = Factors(other);
        double d = 0.0;
        for (int k = 0; k < 7; ++k)
          d = std::max(d, std::abs(std::log(x[k] / y[k])));
        if (d < kMinApart) {
          apart = false;
          break;
        }
      }
      if (apart) break;
    }
    bodies.push_back(b);
  }
  return bodies;
}

std::vector<TemplateBone> IdentityBiped(const BodyProportions& b) {
  BipedProportions p = kAdult;
  p.height *= b.torso_length;
  p.torso_r *= b.torso_thickness;
  p.head_r *= b.head_size;
  p.arm_len *= b.arm_length;
  p.arm_r *= b.arm_thickness;
  p.leg_len *= b.leg_length;
  p.leg_r *= b.leg_thickness;
  return Biped(p);
}

// PoseIdentity poses body `body`; `rest`, when given, receives the body's
// rest skeleton (the template's bones, unplaced).
absl::StatusOr<Posed> PoseIdentity(int body, int pose_index,
                                   const ShapeOptions& options,
                                   Skeleton* rest = nullptr) {
  absl::Status ok = CheckOptions(options, pose_index);
  if (!ok.ok()) return ok;
  absl::StatusOr<BodyProportions> proportions =
      IdentityProportions(body, options);
  if (!proportions.ok()) return proportions.status();
  const std::vector<TemplateBone> bones = IdentityBiped(*proportions);
  if (rest != nullptr) {
    rest->bones.clear();
    for (const TemplateBone& t : bones) rest->bones.push_back(t.bone);
  }
  return PoseTemplate(bones, kIdentityIdBase + body, pose_index, options);
}

absl::StatusOr<Posed> PoseStar(int arms, int pose_index,
                               const ShapeOptions& options) {
  absl::Status ok = CheckOptions(options, pose_index);
  if (!ok.ok()) return ok;
  if (arms < 2 || arms > 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("star arms ", arms, " is outside [2, 8]"));
  }
  return PoseTemplate(Star(arms), kStarIdBase + arms, pose_index, options);
}

}  // namespace

std::vector<std::string> ClassNames() {
  std::vector<std::string> names;
  for (const auto& c : Classes()) names.push_back(c.name);
  return names;
}

int TipCount(const Skeleton& skeleton) {
  const size_t n = skeleton.bones.size();
  std::vector<int> children(n, 0);
  for (const Bone& b : skeleton.bones) {
    if (b.parent >= 0) ++children[b.parent];
  }
  int tips = 0;
  for (size_t i = 0; i < n; ++i) {
    if (children[i] == 0) ++tips;
  }
  // A root with a single child (the snake's head) is an end of the body too.
  if (n > 1 && children[0] == 1) ++tips;
  return tips;
}

absl::StatusOr<Skeleton> PoseSkeleton(absl::string_view class_name,
                                      int pose_index,
                                      const ShapeOptions& options) {
  absl::StatusOr<Posed> posed = PoseClass(class_name, pose_index, options);
  if (!posed.ok()) return posed.status();
  return Place(*posed);
}

absl::StatusOr<extract::Mesh> GenerateShape(absl::string_view class_name,
                                            int pose_index,
                                            const ShapeOptions& options) {
  absl::StatusOr<Posed> posed = PoseClass(class_name, pose_index, options);
  if (!posed.ok()) return posed.status();
  return MeshOf(*posed, options.target_vertices);
}

absl::StatusOr<Skeleton> StarSkeleton(int arms, int pose_index,
                                      const ShapeOptions& options) {
  absl::StatusOr<Posed> posed = PoseStar(arms, pose_index, options);
  if (!posed.ok()) return posed.status();
  return Place(*posed);
}

std::string IdentityBodyName(int body) {
  std::string digits = absl::StrCat(body);
  if (digits.size() < 3) digits.insert(0, 3 - digits.size(), '0');
  return absl::StrCat("body_", digits);
}

absl::StatusOr<BodyProportions> IdentityProportions(
    int body, const ShapeOptions& options) {
  if (body < 0 || body >= kMaxIdentityBodies) {
    return absl::InvalidArgumentError(absl::StrCat(
        "identity body ", body, " is outside [0, ", kMaxIdentityBodies, ")"));
  }
  return DrawBodies(body + 1, options.seed).back();
}

absl::StatusOr<Skeleton> IdentitySkeleton(int body, int pose_index,
                                          const ShapeOptions& options) {
  absl::StatusOr<Posed> posed = PoseIdentity(body, pose_index, options);
  if (!posed.ok()) return posed.status();
  return Place(*posed);
}

absl::StatusOr<extract::Mesh> GenerateIdentity(int body, int pose_index,
                                               const ShapeOptions& options) {
  Skeleton rest;
  absl::StatusOr<Posed> posed = PoseIdentity(body, pose_index, options, &rest);
  if (!posed.ok()) return posed.status();
  if (options.identity_surface == IdentitySurface::kRepolygonized) {
    return MeshOf(*posed, options.target_vertices);
  }
  absl::StatusOr<extract::Mesh> mesh =
      MeshFromSkeleton(rest, options.target_vertices);
  if (!mesh.ok()) return mesh.status();
  return Skin(rest, *posed, std::move(*mesh));
}

absl::StatusOr<extract::Mesh> GenerateStar(int arms,
                                           const ShapeOptions& options) {
  absl::StatusOr<Posed> posed = PoseStar(arms, 0, options);
  if (!posed.ok()) return posed.status();
  return MeshOf(*posed, options.target_vertices);
}

}  // namespace tpr::synth
