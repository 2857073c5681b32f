# The libraries fieldspace builds on (Debian bookworm packages, .ci/install-deps), found by the
# main build and by the fuzz build (fuzz/CMakeLists.txt) alike.
find_package(Eigen3 3.4 REQUIRED CONFIG)
find_package(spectra REQUIRED CONFIG)
find_package(CHOLMOD REQUIRED)
find_package(TBB REQUIRED CONFIG)
find_package(absl REQUIRED CONFIG)
find_package(Protobuf REQUIRED)
find_package(gRPC REQUIRED CONFIG)
find_package(OpenSSL REQUIRED)  # checks the daemon's TLS files (server/tls.cc); gRPC uses it too
find_package(Threads REQUIRED)
