//! tinybvh's BVH8_CPU through src/tinybvh_shim.cpp (why a shim and not tinybvh-rs's Rust API: see there).

use std::ffi::c_void;

// Links tinybvh-rs, whose static library holds the tinybvh definitions the shim calls.
use tinybvh_rs as _;

unsafe extern "C" {
    fn anchors_tinybvh_build(vertices: *const f32, triangles: u32) -> *mut c_void;
    fn anchors_tinybvh_free(bvh: *mut c_void);
    fn anchors_tinybvh_bytes(bvh: *const c_void, traversal: *mut usize) -> usize;
    fn anchors_tinybvh_cast(bvh: *const c_void, rays: *const f32, n: usize, any: i32) -> usize;
    fn anchors_pin(threads: i32) -> i32;
    fn anchors_unpin();
}

/// One vertex as tinybvh reads it: 4 floats, 16-byte aligned (BuildAVX loads them with aligned SSE loads).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
pub struct Vec4(pub [f32; 4]);

/// A built BVH8_CPU, freed on drop.
pub struct Bvh8(*mut c_void);

// The queries are const member functions that keep their state on the stack: safe from many threads at once.
unsafe impl Send for Bvh8 {}
unsafe impl Sync for Bvh8 {}

impl Bvh8 {
    /// Builds over `vertices`, 3 per triangle.
    pub fn build(vertices: &[Vec4]) -> Self {
        assert!(vertices.len() % 3 == 0 && vertices.len() / 3 <= u32::MAX as usize);
        // SAFETY: `vertices` is a live, 16-byte aligned array of 3 × triangles vertices of 4 floats.
        Self(unsafe { anchors_tinybvh_build(vertices.as_ptr().cast(), (vertices.len() / 3) as u32) })
    }

    /// Bytes held, and the bytes the queries read (see the shim).
    pub fn bytes(&self) -> (usize, usize) {
        let mut traversal = 0;
        // SAFETY: `self.0` is a BVH8_CPU built by `build`.
        let held = unsafe { anchors_tinybvh_bytes(self.0, &mut traversal) };
        (held, traversal)
    }

    /// How many of `rays` (origin, direction) hit: the closest-hit query, or with `any` the occlusion query.
    pub fn cast(&self, rays: &[[f32; 6]], any: bool) -> usize {
        // SAFETY: `self.0` is a built BVH8_CPU and `rays` holds rays.len() × 6 floats.
        unsafe { anchors_tinybvh_cast(self.0, rays.as_ptr().cast(), rays.len(), i32::from(any)) }
    }
}

impl Drop for Bvh8 {
    fn drop(&mut self) {
        // SAFETY: `self.0` came from `anchors_tinybvh_build` and is freed once.
        unsafe { anchors_tinybvh_free(self.0) }
    }
}

/// Holds the calling thread to `threads` of its CPUs until the guard drops, so that the worker threads tinybvh's
/// build starts (as many as the machine has CPUs) run on `threads` CPUs only. A no-op where `threads` covers them.
pub struct Pinned(bool);

pub fn pin(threads: usize) -> Pinned {
    // SAFETY: plain sched_{get,set}affinity calls on the calling thread.
    Pinned(unsafe { anchors_pin(i32::try_from(threads).unwrap_or(i32::MAX)) } == 1)
}

impl Drop for Pinned {
    fn drop(&mut self) {
        if self.0 {
            // SAFETY: restores the mask anchors_pin saved.
            unsafe { anchors_unpin() }
        }
    }
}
