// Synthetic articulated shapes: labelled, posable test data for TPR retrieval
// (Tam & Lau 2007, section 7 evaluates on deformable models: one creature in
// many poses). Each class is a tree of tapered bones; a pose bends every joint
// within its limits; the surface is a smooth implicit blend of the bones,
// polygonized into a closed, manifold, genus-0 triangle mesh.
//
//   tpr::synth::ShapeOptions options;            // 10k vertices, seed 1
//   absl::StatusOr<tpr::extract::Mesh> dog =
//       tpr::synth::GenerateShape("quadruped_slender", /*pose_index=*/3,
//                                 options);
#ifndef TPR_EXTRACTOR_SYNTH_SYNTH_H_
#define TPR_EXTRACTOR_SYNTH_SYNTH_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "extractor/lib/mesh.h"

namespace tpr::synth {

// ClassNames returns the shape classes GenerateShape accepts, in a fixed
// order (the order tpr-synth --classes N takes the first N from). There are
// at least 8; "biped_adult"/"biped_child" and
// "quadruped_slender"/"quadruped_stocky" share a skeleton and differ only in
// proportions and thickness. Thread-safe, O(1).
std::vector<std::string> ClassNames();

// IdentitySurface says how identity mode (GenerateIdentity) makes the
// surface of a posed body.
enum class IdentitySurface {
  // Each body's REST mesh (pose_amount 0) is polygonized once
  // (MeshFromSkeleton) and every pose moves its vertices by dual-quaternion
  // skinning (Kavan et al. 2008) with SkinWeights: one skin, rigid along
  // the bones and bent at the joints, the same triangles in every pose of
  // a body. Measured: surface area within 2.1% of the rest mesh's, where
  // spread legs stretch the groin (synth_test, SkinnedPosesKeepOneSkin).
  kSkinned,
  // The posed skeleton is polygonized afresh for every pose (the older
  // identity sets): each pose is a new skin, whose area moves by 0.6 to
  // 1.4% between poses of one body (docs/results.md). Kept to reproduce the
  // earlier identity set.
  kRepolygonized,
};

// ShapeOptions controls one generated mesh.
struct ShapeOptions {
  // Vertices of the output mesh; the result is within 20% of it (exact for
  // the built-in classes). Accepted range [200, 1,000,000]. Default 10,000.
  int target_vertices = 10000;
  // Seed of every random choice (pose angles, rigid motion). Same seed, same
  // class, same pose index: bit-identical mesh. Default 1.
  uint64_t seed = 1;
  // Apply a random rotation, a translation in [-1, 1]^3 and a uniform scale
  // in [1, 2] after posing. The mesh is then exactly the similarity image of
  // the random_rigid = false mesh (same triangles, moved vertices).
  // Default false.
  bool random_rigid = false;
  // Fraction of each joint's angle limit a pose may use: 0 is the rest pose,
  // 1 the full range. Accepted range [0, 1]. Default 1.
  double pose_amount = 1.0;
  // Identity mode only (GenerateIdentity): how a posed body gets its
  // surface. Default kSkinned.
  IdentitySurface identity_surface = IdentitySurface::kSkinned;
};

// Bone is one segment of a skeleton: a capsule from `start` to `end` whose
// radius tapers linearly from `start_radius` to `end_radius`. A bone with
// start == end is a ball.
struct Bone {
  // Index of the parent bone in Skeleton::bones, -1 for the root. Parents
  // come before their children.
  int parent = -1;
  Eigen::Vector3d start = Eigen::Vector3d::Zero();
  Eigen::Vector3d end = Eigen::Vector3d::Zero();
  double start_radius = 0.1;
  double end_radius = 0.1;
  // Short name ("l_forearm"), for debugging and tests.
  std::string name;
};

// Skeleton is a tree of bones (never a loop, so the surface has genus 0).
struct Skeleton {
  std::vector<Bone> bones;
};

// TipCount returns the number of protrusion tips of `skeleton`: bones with no
// child that are meant to end in a tip (every leaf bone). O(bones).
int TipCount(const Skeleton& skeleton);

// PoseSkeleton returns the posed skeleton of `class_name` for
// (options.seed, pose_index), in the frame of the mesh GenerateShape returns
// for the same arguments (rigid motion included). Non-adjacent bones are kept
// apart (poses that would bring limbs into contact are redrawn, then damped
// towards the rest pose), so protrusions stay separated.
// Errors: INVALID_ARGUMENT for an unknown class (the message lists the valid
// ones), a negative pose index or options out of range. Thread-safe, cheap
// (microseconds).
absl::StatusOr<Skeleton> PoseSkeleton(absl::string_view class_name,
                                      int pose_index,
                                      const ShapeOptions& options);

// GenerateShape returns the mesh of `class_name` in pose `pose_index`: closed
// (no boundary edge), edge- and vertex-manifold, one component, genus 0,
// counter-clockwise seen from outside, about options.target_vertices
// vertices. Deterministic in (class, pose_index, options).
// Errors: as PoseSkeleton; INTERNAL if the polygonizer cannot produce a
// genus-0 surface (not seen for the built-in classes).
// Thread-safe. Cost: grows about linearly with target_vertices above ~5k
// (below that the grid the thinnest bone needs dominates); the classes with
// the thinnest parts, ant and octopus, are the slowest (BM_GenerateShape;
// figures in docs/benchmarks.md).
absl::StatusOr<extract::Mesh> GenerateShape(absl::string_view class_name,
                                            int pose_index,
                                            const ShapeOptions& options);

// StarSkeleton returns a ball (radius 0.35) with `arms` cylindrical arms
// (radius 0.1, reaching 1.2 from the centre) spread evenly over the sphere;
// pose `pose_index` bends each arm's outer half by up to 20 degrees
// (pose_amount 0 keeps them straight). Each arm ends in one tip far from the
// centre: the arm tips are the `arms` points farthest from the ball centre.
// Bones: 0 is the ball; arm i is bones 1 + 2i (inner) and 2 + 2i (outer).
// Errors: INVALID_ARGUMENT unless 2 <= arms <= 8, or for options out of
// range. Thread-safe.
absl::StatusOr<Skeleton> StarSkeleton(int arms, int pose_index,
                                      const ShapeOptions& options);

// GenerateStar returns the mesh of StarSkeleton(arms, 0, options), with the
// same guarantees and errors as GenerateShape.
absl::StatusOr<extract::Mesh> GenerateStar(int arms,
                                           const ShapeOptions& options);

// Identity mode: several bodies on one skeleton, the biped's,
// that differ in limb lengths and thickness, each in many poses. Class =
// body: the similar-skeleton case (Tam & Lau 2007, 5.3 and Tables 2-3) in
// unlimited supply, like people of different build in different poses.
//
// Why the poses are skinned: the held-out
// set identity mode stands for ("ten people, ten poses each") consists of
// registrations of real bodies, where a pose is a near-isometric
// deformation of one skin. Re-polygonizing the blended union of the posed
// capsules for every pose (IdentitySurface::kRepolygonized) invents area
// changes no body has (0.6 to 1.4% between poses of one body, scaled
// lambda_2 moving by 4 to 12.6% with a within-body correlation of -0.93;
// docs/results.md). So by default each body is polygonized once at rest and
// every pose deforms that one skin (the area still moves, by up to 2.1%,
// where a pose stretches skin between two limbs, as it does on a body):
//  * Weights (SkinWeights): each rest vertex starts on its nearest bone
//    (the capsule whose part of the blend made it), and the weights are
//    smoothed over the mesh's edges so that they blend over about one mean
//    bone radius along the surface on either side of each junction.
//    Smoothing on the surface keeps parts near in space but not joined
//    (the two thighs at the crotch) from dragging each other. Tried first
//    and dropped: the polygonizer's own field weights exp(-d_i / k) in
//    space, which stretched groin and chin triangles 3.5 times and let
//    body 7's legs pass through each other (8 crossing triangle pairs in
//    one pose); wider falloffs in space made the area change worse (2 to
//    13% at 2, 4, 8 k). Mean bone radius rather than the diameter: with
//    the diameter nothing of the short biped bones stays rigid.
//  * Blending: dual quaternions (Kavan, Collins, Zara, O'Sullivan 2008)
//    rather than linear blend skinning: a linear blend of two rotations is
//    no rotation, and at a bend of angle a with equal weights it shrinks
//    the joint's cross-section by cos(a / 2) (0.89 at the forearm's 55
//    degrees: the "collapsing elbow"), which is exactly the area change the
//    skinning is meant to avoid; a blended unit dual quaternion is a rigid
//    motion per vertex, so distortion comes only from the weights' slope
//    across a joint.
//  * Bone motions: bone i moves rigidly, p -> s_i' + R_i (p - s_i), with s_i
//    and s_i' its start at rest and posed and R_i the forward-kinematics
//    rotation PoseSkeleton applies to it (children inherit their parent's).
//
//   for (int body = 0; body < 10; ++body)
//     for (int pose = 0; pose < 10; ++pose)
//       Write(IdentityBodyName(body), GenerateIdentity(body, pose, options));

// kMaxIdentityBodies bounds the body index of identity mode.
inline constexpr int kMaxIdentityBodies = 1000;

// IdentityBodyName returns "body_<body>" with the index zero-padded to 3
// digits ("body_007"), the class label of identity mode. Thread-safe.
std::string IdentityBodyName(int body);

// BodyProportions are the numbers that tell identity bodies apart, as
// factors of the "biped_adult" class's proportions (1 = the adult).
struct BodyProportions {
  double torso_length = 1.0;  // pelvis top to shoulders
  double torso_thickness = 1.0;
  double head_size = 1.0;
  double arm_length = 1.0;  // upper arm, forearm and hand together
  double arm_thickness = 1.0;
  double leg_length = 1.0;  // thigh, shin and foot together
  double leg_thickness = 1.0;
};

// IdentityProportions returns body `body`'s proportions for options.seed:
// lengths drawn in [0.8, 1.2], thicknesses in [0.8, 1.3], the head in
// [0.85, 1.15], each body at least 0.1 apart from every lower-numbered
// body in the largest absolute log-factor (so no two bodies are near
// twins). Deterministic in (options.seed, body); independent of poses.
// Errors: INVALID_ARGUMENT unless 0 <= body < kMaxIdentityBodies.
// Thread-safe. Cost O(body^2) draws (microseconds for 100 bodies).
absl::StatusOr<BodyProportions> IdentityProportions(
    int body, const ShapeOptions& options);

// IdentitySkeleton returns body `body` in pose `pose_index` (the posing of
// PoseSkeleton, with a seed stream of its own per body), in the frame of
// GenerateIdentity's mesh. Errors: as IdentityProportions and
// PoseSkeleton. Thread-safe.
absl::StatusOr<Skeleton> IdentitySkeleton(int body, int pose_index,
                                          const ShapeOptions& options);

// GenerateIdentity returns the mesh of IdentitySkeleton(body, pose_index,
// options), with GenerateShape's guarantees (closed, manifold, genus 0,
// deterministic), errors and cost. With options.identity_surface kSkinned
// (the default) it is the body's rest mesh (pose_amount 0, seed and pose
// index irrelevant to it) skinned to the pose: every pose of one body has
// the same triangles, and pose_amount 0 gives the rest mesh itself; with
// kRepolygonized, MeshFromSkeleton of the posed skeleton. Cost of
// kSkinned: the rest polygonization plus SkinWeights, whose smoothing
// grows with the square of the vertex count (one thread, measured with
// tpr-synth, load 6: 0.2 s at 5k vertices, 0.9 s at 20k, 6.7 s at 50k;
// re-polygonized 0.14, 0.56 and 1.7 s; about 100 s expected at 200k).
absl::StatusOr<extract::Mesh> GenerateIdentity(int body, int pose_index,
                                               const ShapeOptions& options);

// MeshFromSkeleton polygonizes the smooth blend of `skeleton`'s bones into a
// closed, manifold, genus-0 mesh with about `target_vertices` vertices.
// Preconditions: the skeleton is a tree whose non-adjacent bones do not
// touch. Errors: INVALID_ARGUMENT for an empty skeleton, a bad parent index,
// a non-finite coordinate, a radius <= 0 or target_vertices outside
// [200, 1,000,000]; RESOURCE_EXHAUSTED if the grid the thinnest bone needs
// would exceed 60M points; INTERNAL if the surface is not one genus-0
// component even on a refined grid (e.g. touching bones close a loop).
// Thread-safe. Cost: linear in target_vertices plus the grid the thinnest
// bone forces (spacing = its radius / 1.25; see polygonize.cc).
absl::StatusOr<extract::Mesh> MeshFromSkeleton(const Skeleton& skeleton,
                                               int target_vertices);

// BoneWeight is one bone's share of a skinned vertex.
struct BoneWeight {
  int bone = 0;         // index into Skeleton::bones
  double weight = 0.0;  // in (0, 1]; a vertex's weights sum to 1
};

// SkinWeights returns, for each vertex of `mesh` (polygonized from
// `skeleton`, at rest), the bones it follows and their weights: each vertex
// starts on its nearest bone (the smallest distance to a tapered capsule,
// the field MeshFromSkeleton blends), and the weights are then smoothed over
// the mesh's edges (lazy random walk) so that they blend over about
// +-blend_length along the surface around every junction. Smoothing on the
// surface, not in space, keeps parts that are near in space but not joined
// (the thighs at the crotch, an arm beside the chest) from dragging each
// other. Weights under 1e-6 are dropped; a vertex's weights sum to 1,
// bones listed in increasing index. Preconditions: mesh from
// MeshFromSkeleton(skeleton, ...), blend_length > 0 (not checked).
// Thread-safe. Cost O(vertices x bones x (blend_length / mean edge)^2),
// so quadratic in the vertex count at a fixed shape. A linear-cost
// alternative (Dijkstra from each region, the same erfc profile cut at 3
// blend_length) gave the same area figures but one pair of crossing
// triangles at body 7's neck, so it was not kept.
std::vector<std::vector<BoneWeight>> SkinWeights(const Skeleton& skeleton,
                                                 const extract::Mesh& mesh,
                                                 double blend_length);

}  // namespace tpr::synth

#endif  // TPR_EXTRACTOR_SYNTH_SYNTH_H_
