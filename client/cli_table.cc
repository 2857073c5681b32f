// The one table of the CLI's commands: arguments, flags and help, written once (cli_commands.h).

#include "client/cli_commands.h"

namespace fieldspace::client::cli {
namespace {

// Flags several commands share, spelled once.
const FlagDoc kMuS = {"mu-s", "X"};
const FlagDoc kMuB = {"mu-b", "X"};
const FlagDoc kMuC = {"mu-c", "X"};
const FlagDoc kOut = {"out", "FIELD_FILE"};
const FlagDoc kEncoding = {"encoding", "ambient|dof"};
const FlagDoc kEstimator = {"estimator", "jet|normal-differences"};
const FlagDoc kSingularities = {"singularities", ""};
const FlagDoc kRawWeights = {"raw-weights", ""};
const FlagDoc kBiharmonic = {"biharmonic", "exact|mixed"};
const FlagDoc kFaceWeights = {"face-weights", "FILE"};
const FlagDoc kMode = {"mode", "K"};

}  // namespace

const std::vector<CliCommand>& Commands() {
  static const std::vector<CliCommand> commands = {
      {{"health", "", {{"service", "NAME"}}, "grpc.health.v1 status of the server"}, Health},
      {{"upload",
        "MESH",
        {{"name", "NAME"}, {"format", "obj|off|ply"}},
        "upload a mesh file (format from the extension unless --format); prints MeshInfo "
        "(\"id\")"},
       Upload},
      {{"load",
        "PATH",
        {{"name", "NAME"}},
        "store a mesh file of the server: PATH relative to the daemon's --data-root; prints "
        "MeshInfo (\"id\")"},
       Load},
      {{"meshes", "", {}, "list meshes"}, Meshes},
      {{"mesh", "MESH_ID", {}, "one mesh"}, Mesh},
      {{"delete-mesh",
        "MESH_ID",
        {{"cascade", ""}},
        "delete a mesh (with --cascade: and its bases)"},
       DeleteMesh},
      {{"build",
        "MESH_ID",
        {{"field", "vector|nfield|tensor", true},
         {"n", "N"},
         {"dim", "D", true},
         {"sigma", "S"},
         {"seed", "S"},
         {"fields-per-region", "M"},
         {"coarse-dim", "C"},
         {"quality", "paper|low-modes|smooth"},
         kFaceWeights,
         {"no-kernel-columns", ""},
         {"cancel-on-exit", ""}},
        "build a basis: progress on stderr, BasisInfo (\"id\") on stdout; C > 0 adds a coarse "
        "level of C of the D columns; FILE: #F positive adaptivity weights (smaller regions "
        "where high); --no-kernel-columns: the paper's basis exactly, without the kernel "
        "(harmonic) columns appended by default; Ctrl-C leaves the build running on the server "
        "(and says how to cancel it) unless --cancel-on-exit"},
       Build},
      {{"bases", "", {{"mesh", "MESH_ID"}}, "list bases (and running builds)"}, Bases},
      {{"basis", "BASIS_ID", {}, "one basis"}, Basis},
      {{"delete-basis", "BASIS_ID", {}, "delete a basis"}, DeleteBasis},
      {{"cancel", "BASIS_ID", {}, "cancel a running build"}, Cancel},
      {{"project", "BASIS_ID FIELD_FILE", {}, "coefficients and relative error of the projection"},
       Project},
      {{"solve",
        "BASIS_ID",
        {{"constraints", "FILE", true},
         kMuS,
         kMuB,
         kMuC,
         kOut,
         kEncoding,
         kSingularities,
         kRawWeights,
         kBiharmonic},
        "the model problem with soft/hard constraints (defaults 1, 0, 1; scale-free: a soft "
        "constraint alone pulls its face >= mu_c w / (1 + mu_c w) of the way, unless "
        "--raw-weights); --singularities: also the singular vertices; --biharmonic: the mu_b term "
        "as the subspace's own (mixed, the default: closer to the full space) or the paper's "
        "(exact)"},
       Solve},
      {{"lift",
        "BASIS_ID COEFFS_FILE",
        {kOut, {"faces", "F1,F2,..."}, kEncoding, kMode},
        "the field into FIELD_FILE, or the values of the listed faces as JSON (exactly one of "
        "--out and --faces); --mode K: eigenfield K of `eigen --coefficients` output"},
       Lift},
      {{"eigen",
        "BASIS_ID",
        {{"count", "K", true}, {"coefficients", ""}},
        "the K lowest eigenvalues of the basis (--coefficients: and their eigenfields)"},
       Eigen},
      {{"curvature",
        "MESH_ID",
        {{"out", "FIELD_FILE", true}, kEncoding, kEstimator, {"principal", "FILE"}},
        "the per-face shape operator (1/length) into FIELD_FILE; --principal: per face k1 k2 "
        "d1x d1y d1z d2x d2y d2z"},
       Curvature},
      {{"smoothest",
        "BASIS_ID",
        {kOut, kEncoding},
        "the smoothest unit field (lowest eigenfield) of the basis"},
       Smoothest},
      {{"smooth",
        "BASIS_ID FIELD_FILE",
        {kMuS, kMuB, kMuC, kFaceWeights, kRawWeights, kOut, kEncoding, kSingularities},
        "the field closest to FIELD_FILE (M-weighted) with harmonic and biharmonic fairness; "
        "scale-free weights unless --raw-weights (defaults 0.001, 0, 1)"},
       Smooth},
      {{"align",
        "BASIS_ID",
        {{"curvature", "", true},
         {"n", "2|4"},
         {"smooth-mu", "X"},
         kMuB,
         kMuC,
         kOut,
         kEncoding,
         kEstimator,
         kSingularities},
        "a smooth n-field (n-field basis, n = 2 or 4) aligned to the principal curvature "
        "directions, the only target so far (defaults 0.001, 0, 1)"},
       Align},
      {{"singularities",
        "BASIS_ID COEFFS_FILE",
        {{"zero-tolerance", "T"}, kMode},
        "vertex indices (in turns) of the lifted field"},
       Singularities},
      {{"design",
        "BASIS_ID",
        {{"script", "EDITS.jsonl", true},
         kMuS,
         kMuB,
         kMuC,
         {"mu-a", "X"},
         {"watch", "F1,F2,..."},
         {"no-coefficients", ""},
         kSingularities,
         kRawWeights,
         kBiharmonic,
         {"align-curvature", ""},
         kEstimator,
         {"data", "FIELD_FILE"},
         kFaceWeights},
        "stream edits; one JSON line per update (--singularities: how the singular vertices "
        "changed, in each); weights as solve's; --align-curvature (with --estimator) or --data "
        "FIELD_FILE (with --face-weights): a data term (weight mu_a; then defaults 0.001, 0, 1, "
        "1) the edits act on top of"},
       Design},
      {{"export",
        "MESH FIELD_FILE",
        {{"out", "FILE.vtu|.vtk|.ply|.rawfield", true}},
        "the field on its mesh for ParaView, meshio, Directional; MESH: a mesh id of the server "
        "or a mesh file"},
       nullptr,
       /*python_tool=*/true,
       /*new_group=*/true},
      {{"render",
        "MESH [FIELD_FILE]",
        {{"out", "FILE.png|.jpg", true},
         {"style", "glyphs|streamlines|hatching|lic|surface"},
         {"color", "none|magnitude"},
         {"singularities", "FILE"}},
        "a picture, off screen (VTK); export and render run the Python package's `python3 -m "
        "fieldspace.export|render` (--help: all options)"},
       nullptr,
       /*python_tool=*/true},
  };
  return commands;
}

}  // namespace fieldspace::client::cli
