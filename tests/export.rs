//! glb / bvh / npy export round trips (filled in below).
