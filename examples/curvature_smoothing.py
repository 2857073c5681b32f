#!/usr/bin/env python3
"""Curvature of a noisy mesh, smoothed in a tensor-field subspace (Curvature + Smooth).

Makes a torus and a copy whose vertices are moved a little along their normals, computes the
per-face shape operator (curvature tensor, a symmetric (1,1)-tensor field) of both, and smooths
the noisy one with Smooth in a tensor basis of the noisy mesh. Prints how far the raw and the
smoothed tensors are from the clean mesh's (relative, area-weighted Frobenius norm) and the
principal curvatures against the torus's exact ones.

    examples/curvature_smoothing.py --server 127.0.0.1:50051
"""

import argparse
import sys

import numpy as np

import fieldspace

R, r = 1.0, 0.4  # the torus's radii


def torus(major=96, minor=32):
    """(V, F, vertex normals, the angle v around the tube of each vertex)."""
    u = 2 * np.pi * np.arange(major) / major
    v = 2 * np.pi * np.arange(minor) / minor
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack([(R + r * np.cos(W)) * np.cos(U), (R + r * np.cos(W)) * np.sin(U),
                  r * np.sin(W)], axis=-1).reshape(-1, 3)
    N = np.stack([np.cos(W) * np.cos(U), np.cos(W) * np.sin(U), np.sin(W)],
                 axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(major), np.arange(minor), indexing="ij")
    a, b = i * minor + j, ((i + 1) % major) * minor + j
    c, d = ((i + 1) % major) * minor + (j + 1) % minor, i * minor + (j + 1) % minor
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)]).astype(np.int32)
    return V, F, N, W.ravel()


def areas(V, F):
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                axis=1)


def relative_error(K, reference, area):
    diff = np.sum((K - reference) ** 2, axis=(1, 2))
    return float(np.sqrt(np.sum(area * diff) / np.sum(area * np.sum(reference ** 2, axis=(1, 2)))))


def principal(K, V, F):
    """k1 >= k2 of per-face tensors: the eigenvalues in the face's tangent plane."""
    x = V[F[:, 1]] - V[F[:, 0]]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    T = np.stack([x, np.cross(n, x)], axis=2)  # (F, 3, 2)
    k = np.linalg.eigvalsh(np.swapaxes(T, 1, 2) @ K @ T)
    return k[:, 1], k[:, 0]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="HOST:PORT of fieldspaced")
    parser.add_argument("--token", help="a file with the server's token, if it needs one")
    parser.add_argument("--dim", type=int, default=400, help="tensor basis dimension")
    parser.add_argument("--noise", type=float, default=0.1,
                        help="vertex noise along the normals, in mean edge lengths")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    token = open(args.token).read() if args.token else None
    client = fieldspace.Client(args.server, token=token, timeout=120)

    V, F, N, tube_angle = torus()
    edge = np.mean(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1))
    rng = np.random.default_rng(args.seed)
    noisy_V = V + (args.noise * edge * rng.uniform(-1, 1, len(V)))[:, None] * N
    clean = client.upload(V, F, name="torus")
    noisy = client.upload(noisy_V, F, name="noisy torus")
    print("torus: %d faces, noise %.2g mean edge lengths along the normals" % (
        len(F), args.noise))

    K_clean = client.curvature(clean.id).tensor  # (F, 3, 3), 1/length
    K_noisy = client.curvature(noisy.id).tensor
    area = areas(V, F)
    basis = client.build(noisy.id, "tensor", args.dim)
    rows = [("raw curvature of the noisy mesh", K_noisy)]
    projected = client.lift(basis, client.project(basis, K_noisy).coefficients)
    rows.append(("projected into the basis (d = %d)" % args.dim, projected))
    for mu_s in (1e-5, 1e-4, 1e-3):
        smoothed = client.smooth(basis, K_noisy, weights=(mu_s, 0.0, 1.0), return_field=True)
        rows.append(("smoothed, mu_s = %g (%.1f ms)" % (mu_s, smoothed.timings["total_ms"]),
                     smoothed.field))

    # The exact principal curvatures of the torus at the faces' mean tube angle.
    v = np.angle(np.exp(1j * tube_angle[F]).mean(axis=1))
    exact = np.sort(np.stack([np.full(len(F), 1 / r), np.cos(v) / (R + r * np.cos(v))]), axis=0)
    k_exact_1, k_exact_2 = exact[1], exact[0]
    clean_k1, clean_k2 = principal(K_clean, V, F)
    sign = np.sign(np.median(clean_k1))  # the faces' orientation decides the sign
    print("clean mesh vs exact: k1 %.3f, k2 %.3f (mean |error|)" % (
        np.mean(np.abs(sign * clean_k1 - k_exact_1)), np.mean(np.abs(sign * clean_k2 - k_exact_2))))
    print("%-42s %12s %14s %14s" % ("", "tensor error", "|k1 - exact|", "|k2 - exact|"))
    errors = []
    for name, K in rows:
        k1, k2 = principal(K, noisy_V, F)
        errors.append(relative_error(K, K_clean, area))
        print("%-42s %12.3f %14.3f %14.3f" % (name, errors[-1], np.mean(np.abs(sign * k1 -
                                                                             k_exact_1)),
                                              np.mean(np.abs(sign * k2 - k_exact_2))))
    best = int(np.argmin(errors[2:])) + 2
    print("best: %s, %.1fx closer to the clean curvature than the raw one" % (
        rows[best][0].split(" (")[0], errors[0] / errors[best]))
    return 0 if errors[best] < 0.5 * errors[0] else 1


if __name__ == "__main__":
    sys.exit(main())
