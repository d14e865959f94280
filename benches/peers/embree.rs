//! Embree 3 through its C API, for benchmarks only (feature `embree`; Debian's `libembree-dev`).
//!
//! Hand-written bindings for the few calls the benches need: a triangle scene with
//! `rtcIntersect1` / `rtcOccluded1` / `rtcIntersect8`, and `rtcBuildBVH` (Embree's own builder over
//! user boxes) whose tree is handed back through callbacks so its SAH cost can be computed the same
//! way as strahl's. The device runs with one thread (`threads=1`), as strahl's builders do.
#![allow(dead_code, non_camel_case_types, non_snake_case, clippy::upper_case_acronyms)]

use std::ffi::{CString, c_char, c_uint, c_void};
use std::ptr::{null, null_mut};
use strahl::{Aabb, Ray, Vec3};

type RTCDevice = *mut c_void;
type RTCScene = *mut c_void;
type RTCGeometry = *mut c_void;
type RTCBVH = *mut c_void;
type RTCThreadLocalAllocator = *mut c_void;

const RTC_GEOMETRY_TYPE_TRIANGLE: c_uint = 0;
const RTC_GEOMETRY_TYPE_INSTANCE: c_uint = 121;
const RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR: c_uint = 0x9234;
const RTC_BUFFER_TYPE_INDEX: c_uint = 0;
const RTC_BUFFER_TYPE_VERTEX: c_uint = 1;
const RTC_FORMAT_UINT3: c_uint = 0x5003;
const RTC_FORMAT_FLOAT3: c_uint = 0x9003;
const RTC_INVALID_GEOMETRY_ID: c_uint = u32::MAX;
const RTC_SCENE_FLAG_ROBUST: c_uint = 1 << 2;
const RTC_SCENE_FLAG_DYNAMIC: c_uint = 1 << 0;
const RTC_BUILD_QUALITY_REFIT: c_uint = 3;

/// Embree's build quality levels.
#[derive(Clone, Copy, Debug)]
#[repr(u32)]
pub enum Quality {
    /// Morton-code builder.
    Low = 0,
    /// Binned SAH.
    Medium = 1,
    /// Binned SAH with spatial splits (scenes) / higher quality (rtcBuildBVH).
    High = 2,
}

#[repr(C)]
struct RTCIntersectContext {
    flags: c_uint,
    filter: *const c_void,
    inst_id: [c_uint; 1],
}

#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RTCRay {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: c_uint,
    id: c_uint,
    flags: c_uint,
}

#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RTCHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: c_uint,
    geom_id: c_uint,
    inst_id: [c_uint; 1],
}

#[repr(C)]
#[derive(Clone, Copy)]
struct RTCRayHit {
    ray: RTCRay,
    hit: RTCHit,
}

#[repr(C, align(32))]
struct RTCRayHit8 {
    org_x: [f32; 8],
    org_y: [f32; 8],
    org_z: [f32; 8],
    tnear: [f32; 8],
    dir_x: [f32; 8],
    dir_y: [f32; 8],
    dir_z: [f32; 8],
    time: [f32; 8],
    tfar: [f32; 8],
    mask: [c_uint; 8],
    id: [c_uint; 8],
    flags: [c_uint; 8],
    ng_x: [f32; 8],
    ng_y: [f32; 8],
    ng_z: [f32; 8],
    u: [f32; 8],
    v: [f32; 8],
    prim_id: [c_uint; 8],
    geom_id: [c_uint; 8],
    inst_id: [c_uint; 8],
}

#[repr(C, align(32))]
#[derive(Clone, Copy)]
struct RTCBuildPrimitive {
    lower: [f32; 3],
    geom_id: c_uint,
    upper: [f32; 3],
    prim_id: c_uint,
}

#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RTCBounds {
    lower: [f32; 3],
    align0: f32,
    upper: [f32; 3],
    align1: f32,
}

type CreateNode = extern "C" fn(RTCThreadLocalAllocator, c_uint, *mut c_void) -> *mut c_void;
type SetChildren = extern "C" fn(*mut c_void, *mut *mut c_void, c_uint, *mut c_void);
type SetBounds = extern "C" fn(*mut c_void, *const *const RTCBounds, c_uint, *mut c_void);
type CreateLeaf = extern "C" fn(RTCThreadLocalAllocator, *const RTCBuildPrimitive, usize, *mut c_void) -> *mut c_void;

#[repr(C)]
struct RTCBuildArguments {
    byte_size: usize,
    build_quality: c_uint,
    build_flags: c_uint,
    max_branching_factor: c_uint,
    max_depth: c_uint,
    sah_block_size: c_uint,
    min_leaf_size: c_uint,
    max_leaf_size: c_uint,
    traversal_cost: f32,
    intersection_cost: f32,
    bvh: RTCBVH,
    primitives: *mut RTCBuildPrimitive,
    primitive_count: usize,
    primitive_array_capacity: usize,
    create_node: Option<CreateNode>,
    set_node_children: Option<SetChildren>,
    set_node_bounds: Option<SetBounds>,
    create_leaf: Option<CreateLeaf>,
    split_primitive: *const c_void,
    build_progress: *const c_void,
    user_ptr: *mut c_void,
}

/// Embree's `RTCFilterFunctionNArguments`: the candidate hits of `N` rays (SoA `RTCRayN` and
/// `RTCHitN`); the filter clears `valid[i]` to reject hit `i`.
#[repr(C)]
pub struct RTCFilterFunctionNArguments {
    valid: *mut i32,
    geometry_user_ptr: *mut c_void,
    context: *mut RTCIntersectContext,
    ray: *mut f32,
    hit: *mut f32,
    n: c_uint,
}

/// A filter callback (`RTCFilterFunctionN`).
pub type RTCFilterFunctionN = unsafe extern "C" fn(args: *const RTCFilterFunctionNArguments);

/// The filter the trace bench gives Embree: keeps every hit whose distance is finite (all of
/// them), read from the ray's `tfar` as a filter that looked at the hit would; the same work as
/// strahl's `|h: &Hit| h.t.is_finite()`, through Embree's callback interface.
///
/// # Safety
/// Called by Embree only, with its arguments for `N` rays.
pub unsafe extern "C" fn keep_finite_t(args: *const RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes valid arguments: `valid` and the SoA ray of `n` lanes, `tfar` at
    // float offset `8 n` (org xyz, tnear, dir xyz, time, then tfar).
    unsafe {
        let a = &*args;
        let n = a.n as usize;
        for i in 0..n {
            if *a.valid.add(i) != 0 && !(*a.ray.add(8 * n + i)).is_finite() {
                *a.valid.add(i) = 0;
            }
        }
    }
}

/// The alpha-test stand-in of the trace bench: rejects the hits of odd primitives (read from
/// the hit's `primID`), as strahl's `|h: &Hit| h.prim % 2 == 0` does.
///
/// # Safety
/// Called by Embree only, with its arguments for `N` rays.
pub unsafe extern "C" fn keep_even_prims(args: *const RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes valid arguments: `valid` and the SoA hit of `n` lanes, `primID` at
    // 32-bit offset `5 n` (Ng xyz, u, v, then primID).
    unsafe {
        let a = &*args;
        let n = a.n as usize;
        for i in 0..n {
            let prim = (*a.hit.add(5 * n + i)).to_bits();
            if *a.valid.add(i) != 0 && prim % 2 == 1 {
                *a.valid.add(i) = 0;
            }
        }
    }
}

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcSetGeometryIntersectFilterFunction(geometry: RTCGeometry, filter: Option<RTCFilterFunctionN>);
    fn rtcSetGeometryOccludedFilterFunction(geometry: RTCGeometry, filter: Option<RTCFilterFunctionN>);
    fn rtcNewDevice(config: *const c_char) -> RTCDevice;
    fn rtcReleaseDevice(device: RTCDevice);
    fn rtcGetDeviceError(device: RTCDevice) -> c_uint;
    fn rtcNewScene(device: RTCDevice) -> RTCScene;
    fn rtcReleaseScene(scene: RTCScene);
    fn rtcSetSceneBuildQuality(scene: RTCScene, quality: c_uint);
    fn rtcSetSceneFlags(scene: RTCScene, flags: c_uint);
    fn rtcCommitScene(scene: RTCScene);
    fn rtcNewGeometry(device: RTCDevice, ty: c_uint) -> RTCGeometry;
    fn rtcReleaseGeometry(geometry: RTCGeometry);
    fn rtcCommitGeometry(geometry: RTCGeometry);
    fn rtcSetGeometryBuildQuality(geometry: RTCGeometry, quality: c_uint);
    fn rtcSetNewGeometryBuffer(
        geometry: RTCGeometry,
        ty: c_uint,
        slot: c_uint,
        format: c_uint,
        stride: usize,
        count: usize,
    ) -> *mut c_void;
    fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> c_uint;
    fn rtcSetSharedGeometryBuffer(
        geometry: RTCGeometry,
        ty: c_uint,
        slot: c_uint,
        format: c_uint,
        ptr: *const c_void,
        byte_offset: usize,
        byte_stride: usize,
        count: usize,
    );
    fn rtcUpdateGeometryBuffer(geometry: RTCGeometry, ty: c_uint, slot: c_uint);
    fn rtcSetGeometryInstancedScene(geometry: RTCGeometry, scene: RTCScene);
    fn rtcSetGeometryTransform(geometry: RTCGeometry, time_step: c_uint, format: c_uint, xfm: *const c_void);
    fn rtcSetGeometryMask(geometry: RTCGeometry, mask: c_uint);
    fn rtcGetGeometry(scene: RTCScene, geom_id: c_uint) -> RTCGeometry;
    fn rtcGetDeviceProperty(device: RTCDevice, prop: c_uint) -> isize;
    fn rtcIntersect1(scene: RTCScene, ctx: *mut RTCIntersectContext, rayhit: *mut RTCRayHit);
    fn rtcOccluded1(scene: RTCScene, ctx: *mut RTCIntersectContext, ray: *mut RTCRay);
    fn rtcIntersect1M(scene: RTCScene, ctx: *mut RTCIntersectContext, rayhit: *mut RTCRayHit, m: c_uint, stride: usize);
    fn rtcOccluded1M(scene: RTCScene, ctx: *mut RTCIntersectContext, ray: *mut RTCRay, m: c_uint, stride: usize);
    fn rtcIntersect8(valid: *const i32, scene: RTCScene, ctx: *mut RTCIntersectContext, rayhit: *mut RTCRayHit8);
    fn rtcNewBVH(device: RTCDevice) -> RTCBVH;
    fn rtcBuildBVH(args: *const RTCBuildArguments) -> *mut c_void;
    fn rtcThreadLocalAlloc(alloc: RTCThreadLocalAllocator, bytes: usize, align: usize) -> *mut c_void;
    fn rtcReleaseBVH(bvh: RTCBVH);
}

/// The rays `STREAM` at a time: each copied into Embree's layout by `make` (into a buffer of
/// `empty`s on the stack), the stream traced by `trace`, then `read(i, &e)` for ray `i`.
fn in_streams<E: Copy>(
    rays: &[Ray],
    empty: E,
    make: impl Fn(&Ray) -> E,
    mut trace: impl FnMut(&mut [E]),
    mut read: impl FnMut(usize, &E),
) {
    let mut buf = [empty; STREAM];
    for (k, chunk) in rays.chunks(STREAM).enumerate() {
        for (b, r) in buf.iter_mut().zip(chunk) {
            *b = make(r);
        }
        trace(&mut buf[..chunk.len()]);
        for (i, b) in buf[..chunk.len()].iter().enumerate() {
            read(k * STREAM + i, b);
        }
    }
}

/// Rays per call of Embree's stream API in [`Scene::intersect1m`] (Embree's own tutorials
/// stream a tile's rays at a time; 256 is a 16 x 16 tile).
pub const STREAM: usize = 256;

fn context() -> RTCIntersectContext {
    RTCIntersectContext {
        flags: 0,
        filter: null(),
        inst_id: [RTC_INVALID_GEOMETRY_ID],
    }
}

/// An Embree device (one thread unless made with [`Device::with_threads`]).
pub struct Device(RTCDevice);

impl Device {
    /// A device restricted to one build and render thread.
    pub fn single_threaded() -> Self {
        Self::with_threads(1)
    }

    /// A device with `threads` build and render threads (Embree's TBB pool).
    pub fn with_threads(threads: usize) -> Self {
        let cfg = CString::new(format!("threads={}", threads.max(1))).expect("no NUL");
        // SAFETY: a valid NUL-terminated config string; Embree returns null on failure (checked).
        let d = unsafe { rtcNewDevice(cfg.as_ptr()) };
        assert!(!d.is_null(), "rtcNewDevice failed");
        Self(d)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the device was created by rtcNewDevice and is released once.
        unsafe { rtcReleaseDevice(self.0) }
    }
}

/// A committed triangle scene.
pub struct Scene<'d> {
    scene: RTCScene,
    _device: &'d Device,
}

impl<'d> Scene<'d> {
    /// Builds Embree's BVH over `tris` (one triangle mesh) with `quality`.
    pub fn new(device: &'d Device, tris: &[[Vec3; 3]], quality: Quality) -> Self {
        Self::with_flags(device, tris, quality, false)
    }

    /// [`new`](Self::new), in Embree's robust mode if `robust` (`RTC_SCENE_FLAG_ROBUST`: "uses
    /// acceleration structures that allow for robust traversal, and avoids optimizations that
    /// reduce arithmetic accuracy").
    #[allow(dead_code)] // used by some bench targets only
    pub fn with_flags(device: &'d Device, tris: &[[Vec3; 3]], quality: Quality, robust: bool) -> Self {
        Self::with_filter(device, tris, quality, robust, None)
    }

    /// [`with_flags`](Self::with_flags), with `filter` as the geometry's intersection and
    /// occlusion filter function (Embree's way of alpha testing).
    #[allow(dead_code)] // used by some bench targets only
    pub fn with_filter(
        device: &'d Device,
        tris: &[[Vec3; 3]],
        quality: Quality,
        robust: bool,
        filter: Option<RTCFilterFunctionN>,
    ) -> Self {
        // SAFETY: standard Embree scene setup on a live device; the buffers Embree allocates are
        // written within their sizes (3 floats per vertex, 3 u32 per triangle) before commit.
        unsafe {
            let scene = rtcNewScene(device.0);
            rtcSetSceneBuildQuality(scene, quality as c_uint);
            if robust {
                rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
            }
            let geom = rtcNewGeometry(device.0, RTC_GEOMETRY_TYPE_TRIANGLE);
            rtcSetGeometryBuildQuality(geom, quality as c_uint);
            let vb = rtcSetNewGeometryBuffer(
                geom,
                RTC_BUFFER_TYPE_VERTEX,
                0,
                RTC_FORMAT_FLOAT3,
                12,
                tris.len() * 3 + 1,
            ) as *mut f32;
            let ib =
                rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, tris.len()) as *mut u32;
            assert!(!vb.is_null() && !ib.is_null(), "Embree buffer allocation failed");
            let v = std::slice::from_raw_parts_mut(vb, tris.len() * 9);
            let idx = std::slice::from_raw_parts_mut(ib, tris.len() * 3);
            for (i, t) in tris.iter().enumerate() {
                for (j, p) in t.iter().enumerate() {
                    v[i * 9 + j * 3..i * 9 + j * 3 + 3].copy_from_slice(&p.to_array());
                    idx[i * 3 + j] = (i * 3 + j) as u32;
                }
            }
            if filter.is_some() {
                rtcSetGeometryIntersectFilterFunction(geom, filter);
                rtcSetGeometryOccludedFilterFunction(geom, filter);
            }
            rtcCommitGeometry(geom);
            rtcAttachGeometry(scene, geom);
            rtcReleaseGeometry(geom);
            rtcCommitScene(scene);
            assert_eq!(rtcGetDeviceError(device.0), 0, "Embree reported an error");
            Self { scene, _device: device }
        }
    }

    fn ray(r: &Ray) -> RTCRay {
        RTCRay {
            org: r.origin.to_array(),
            tnear: r.tmin,
            dir: r.direction.to_array(),
            time: 0.0,
            tfar: r.tmax,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        }
    }

    /// Closest hit: `(t, primitive)`.
    #[inline]
    pub fn intersect1(&self, r: &Ray) -> Option<(f32, u32)> {
        intersect1(self.scene, r, u32::MAX)
    }

    /// Any hit in `[tmin, tmax]`.
    #[inline]
    pub fn occluded1(&self, r: &Ray) -> bool {
        occluded1(self.scene, r, u32::MAX)
    }

    /// Embree's stream API over a batch (`rtcIntersect1M`, as many rays per call as
    /// [`STREAM`]): the rays copied into Embree's layout a stream at a time, the context flag
    /// `coherent` (`RTC_INTERSECT_CONTEXT_FLAG_COHERENT`, else `..._INCOHERENT`) telling Embree
    /// which kind they are; `out(i, (t, primitive))` for each ray. The copying is part of what a
    /// caller holding its own rays pays.
    pub fn intersect1m(&self, rays: &[Ray], coherent: bool, mut out: impl FnMut(usize, Option<(f32, u32)>)) {
        intersect1m(self.scene, rays, coherent, &mut out);
    }

    /// Embree's stream API for any-hit rays (`rtcOccluded1M`), as [`intersect1m`](Self::intersect1m).
    pub fn occluded1m(&self, rays: &[Ray], coherent: bool, mut out: impl FnMut(usize, bool)) {
        occluded1m(self.scene, rays, coherent, &mut out);
    }

    /// Eight rays as one packet: `(t, primitive)` per lane.
    pub fn intersect8(&self, rays: &[Ray]) -> [Option<(f32, u32)>; 8] {
        let mut valid = [0i32; 8];
        // SAFETY: an all-zero RTCRayHit8 is a valid value (plain floats and integers).
        let mut rh: RTCRayHit8 = unsafe { std::mem::zeroed() };
        for (i, r) in rays.iter().take(8).enumerate() {
            valid[i] = -1;
            [rh.org_x[i], rh.org_y[i], rh.org_z[i]] = r.origin.to_array();
            [rh.dir_x[i], rh.dir_y[i], rh.dir_z[i]] = r.direction.to_array();
            rh.tnear[i] = r.tmin;
            rh.tfar[i] = r.tmax;
            rh.mask[i] = u32::MAX;
            rh.geom_id[i] = RTC_INVALID_GEOMETRY_ID;
        }
        let mut ctx = context();
        ctx.flags = 1; // coherent
        // SAFETY: `valid` has 8 ints, `rh` is 32-byte aligned and initialised.
        unsafe { rtcIntersect8(valid.as_ptr(), self.scene, &mut ctx, &mut rh) };
        std::array::from_fn(|i| (rh.geom_id[i] != RTC_INVALID_GEOMETRY_ID).then_some((rh.tfar[i], rh.prim_id[i])))
    }
}

impl Drop for Scene<'_> {
    fn drop(&mut self) {
        // SAFETY: created by rtcNewScene, released once.
        unsafe { rtcReleaseScene(self.scene) }
    }
}

/// Embree's instancing: one triangle-mesh scene (the BLAS) and a top scene of instances of it,
/// each with an object-to-world transform (3 x 4, column-major: the three axes, then the
/// translation).
#[allow(dead_code)] // used by some bench targets only
pub struct InstanceScene<'d> {
    scene: RTCScene,
    /// Instance geometries in the top scene (ids `0..instances`).
    instances: usize,
    _blas: Scene<'d>,
}

#[allow(dead_code)] // used by some bench targets only
impl<'d> InstanceScene<'d> {
    /// Builds the BLAS over `tris` and the top scene over `transforms`, both at `quality`.
    pub fn new(device: &'d Device, tris: &[[Vec3; 3]], transforms: &[[f32; 12]], quality: Quality) -> Self {
        Self::with_masks(device, tris, transforms, &[], quality)
    }

    /// [`new`](Self::new) with a geometry mask per instance (`rtcSetGeometryMask`; instances
    /// past `masks` keep Embree's default, all ones), for [`intersect1_masked`](Self::intersect1_masked).
    /// The device must support ray masks (Debian's Embree 3 does: `RTC_DEVICE_PROPERTY_RAY_MASK_SUPPORTED`).
    pub fn with_masks(
        device: &'d Device,
        tris: &[[Vec3; 3]],
        transforms: &[[f32; 12]],
        masks: &[u32],
        quality: Quality,
    ) -> Self {
        const RTC_DEVICE_PROPERTY_RAY_MASK_SUPPORTED: c_uint = 64;
        // SAFETY: a property query on a live device.
        let masks_work = unsafe { rtcGetDeviceProperty(device.0, RTC_DEVICE_PROPERTY_RAY_MASK_SUPPORTED) } != 0;
        assert!(
            masks.is_empty() || masks_work,
            "this Embree was built without ray masks (EMBREE_RAY_MASK)"
        );
        let blas = Scene::new(device, tris, quality);
        // SAFETY: standard Embree instance setup on a live device: the instanced scene is
        // committed (by `Scene::new`) and outlives the top scene (kept in `_blas`, dropped after
        // `scene`'s release in `drop`); each transform is 12 floats, copied by Embree.
        unsafe {
            let scene = rtcNewScene(device.0);
            rtcSetSceneBuildQuality(scene, quality as c_uint);
            for (i, xfm) in transforms.iter().enumerate() {
                let g = rtcNewGeometry(device.0, RTC_GEOMETRY_TYPE_INSTANCE);
                rtcSetGeometryInstancedScene(g, blas.scene);
                rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm.as_ptr().cast());
                if let Some(&m) = masks.get(i) {
                    rtcSetGeometryMask(g, m);
                }
                rtcCommitGeometry(g);
                rtcAttachGeometry(scene, g);
                rtcReleaseGeometry(g);
            }
            rtcCommitScene(scene);
            assert_eq!(rtcGetDeviceError(device.0), 0, "Embree reported an error");
            Self {
                scene,
                instances: transforms.len(),
                _blas: blas,
            }
        }
    }

    /// Closest hit: `(t, primitive)`.
    #[inline]
    pub fn intersect1(&self, r: &Ray) -> Option<(f32, u32)> {
        intersect1(self.scene, r, u32::MAX)
    }

    /// Any hit in `[tmin, tmax]`.
    #[inline]
    pub fn occluded1(&self, r: &Ray) -> bool {
        occluded1(self.scene, r, u32::MAX)
    }

    /// Closest hit among the instances whose mask shares a bit with `mask`: `(t, primitive)`.
    #[inline]
    pub fn intersect1_masked(&self, r: &Ray, mask: u32) -> Option<(f32, u32)> {
        intersect1(self.scene, r, mask)
    }

    /// Any hit in `[tmin, tmax]` among the instances whose mask shares a bit with `mask`.
    #[inline]
    pub fn occluded1_masked(&self, r: &Ray, mask: u32) -> bool {
        occluded1(self.scene, r, mask)
    }

    /// Moves the instances: a new transform for each (as many as given to [`new`](Self::new)),
    /// each instance geometry committed, then the top scene (Embree rebuilds its instance-level
    /// BVH at the scene's quality; the instanced scene is untouched).
    pub fn set_transforms(&mut self, transforms: &[[f32; 12]]) {
        assert_eq!(transforms.len(), self.instances, "one transform per instance");
        // SAFETY: the top scene is live and its geometries were attached in order, so their ids
        // are 0..n; `rtcGetGeometry` returns null past them, which is checked. Each transform is
        // 12 floats, copied by Embree.
        unsafe {
            for (i, xfm) in transforms.iter().enumerate() {
                let g = rtcGetGeometry(self.scene, i as c_uint);
                assert!(!g.is_null(), "no instance {i}");
                rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm.as_ptr().cast());
                rtcCommitGeometry(g);
            }
            rtcCommitScene(self.scene);
        }
    }

    /// Embree's stream API through the instances (`rtcIntersect1M`, as [`Scene::intersect1m`]).
    pub fn intersect1m(&self, rays: &[Ray], coherent: bool, mut out: impl FnMut(usize, Option<(f32, u32)>)) {
        intersect1m(self.scene, rays, coherent, &mut out);
    }
}

impl Drop for InstanceScene<'_> {
    fn drop(&mut self) {
        // SAFETY: created by rtcNewScene, released once (before the instanced scene).
        unsafe { rtcReleaseScene(self.scene) }
    }
}

/// `rtcIntersect1M` on `scene` (see [`Scene::intersect1m`]).
fn intersect1m(scene: RTCScene, rays: &[Ray], coherent: bool, out: &mut impl FnMut(usize, Option<(f32, u32)>)) {
    let empty = RTCRayHit {
        ray: Scene::ray(&Ray::new(Vec3::ZERO, Vec3::X)),
        hit: RTCHit {
            ng: [0.0; 3],
            u: 0.0,
            v: 0.0,
            prim_id: 0,
            geom_id: RTC_INVALID_GEOMETRY_ID,
            inst_id: [0],
        },
    };
    in_streams(
        rays,
        empty,
        |r| RTCRayHit {
            ray: Scene::ray(r),
            ..empty
        },
        |buf| {
            let mut ctx = context();
            ctx.flags = coherent as c_uint;
            // SAFETY: `buf` holds `buf.len()` initialised, aligned RTCRayHits, each
            // `size_of::<RTCRayHit>()` bytes after the last; the scene is live and committed.
            unsafe {
                rtcIntersect1M(
                    scene,
                    &mut ctx,
                    buf.as_mut_ptr(),
                    buf.len() as c_uint,
                    std::mem::size_of::<RTCRayHit>(),
                )
            }
        },
        |i, b| {
            out(
                i,
                (b.hit.geom_id != RTC_INVALID_GEOMETRY_ID).then_some((b.ray.tfar, b.hit.prim_id)),
            )
        },
    );
}

/// `rtcOccluded1M` on `scene` (see [`Scene::occluded1m`]).
fn occluded1m(scene: RTCScene, rays: &[Ray], coherent: bool, out: &mut impl FnMut(usize, bool)) {
    in_streams(
        rays,
        Scene::ray(&Ray::new(Vec3::ZERO, Vec3::X)),
        Scene::ray,
        |buf| {
            let mut ctx = context();
            ctx.flags = coherent as c_uint;
            // SAFETY: as in `intersect1m`, with RTCRays.
            unsafe {
                rtcOccluded1M(
                    scene,
                    &mut ctx,
                    buf.as_mut_ptr(),
                    buf.len() as c_uint,
                    std::mem::size_of::<RTCRay>(),
                )
            }
        },
        |i, b| out(i, b.tfar == f32::NEG_INFINITY),
    );
}

/// `rtcIntersect1` on a committed scene with ray mask `mask`: `(t, primitive)` of the closest
/// hit.
#[inline]
fn intersect1(scene: RTCScene, r: &Ray, mask: u32) -> Option<(f32, u32)> {
    let mut rh = RTCRayHit {
        ray: RTCRay { mask, ..Scene::ray(r) },
        hit: RTCHit {
            ng: [0.0; 3],
            u: 0.0,
            v: 0.0,
            prim_id: 0,
            geom_id: RTC_INVALID_GEOMETRY_ID,
            inst_id: [0],
        },
    };
    let mut ctx = context();
    // SAFETY: `rh` and `ctx` are valid, aligned, initialised structs for the call's duration;
    // `scene` is a live, committed scene (the callers hold it).
    unsafe { rtcIntersect1(scene, &mut ctx, &mut rh) };
    (rh.hit.geom_id != RTC_INVALID_GEOMETRY_ID).then_some((rh.ray.tfar, rh.hit.prim_id))
}

/// `rtcOccluded1` on a committed scene with ray mask `mask`: any hit in `[tmin, tmax]`.
#[inline]
fn occluded1(scene: RTCScene, r: &Ray, mask: u32) -> bool {
    let mut ray = RTCRay { mask, ..Scene::ray(r) };
    let mut ctx = context();
    // SAFETY: as in `intersect1`.
    unsafe { rtcOccluded1(scene, &mut ctx, &mut ray) };
    ray.tfar == f32::NEG_INFINITY
}

/// A dynamic scene of one triangle mesh whose geometry is refitted on every commit: the scene at
/// `RTC_BUILD_QUALITY_LOW` (a two-level structure, the only mode in which Embree reads a
/// geometry's build quality), the geometry at `RTC_BUILD_QUALITY_REFIT`, `RTC_SCENE_FLAG_DYNAMIC`;
/// its vertices in a buffer shared with Embree (no copy per refit, as an engine animating a mesh
/// would set it up).
#[allow(dead_code)] // used by some bench targets only
pub struct RefitScene<'d> {
    scene: RTCScene,
    geom: RTCGeometry,
    /// Nine floats per triangle and Embree's 16 bytes of read padding; never reallocated.
    vertices: Vec<f32>,
    _indices: Vec<u32>,
    _device: &'d Device,
}

#[allow(dead_code)]
impl<'d> RefitScene<'d> {
    /// Builds the scene over `tris`.
    pub fn new(device: &'d Device, tris: &[[Vec3; 3]]) -> Self {
        let mut vertices = vec![0.0f32; tris.len() * 9 + 4];
        let indices: Vec<u32> = (0..tris.len() as u32 * 3).collect();
        for (i, t) in tris.iter().enumerate() {
            for (j, p) in t.iter().enumerate() {
                vertices[i * 9 + j * 3..i * 9 + j * 3 + 3].copy_from_slice(&p.to_array());
            }
        }
        // SAFETY: standard Embree setup on a live device; the shared buffers outlive the scene
        // (owned by `Self`, released after it in `drop`), are never reallocated, and hold their
        // counts of items (plus Embree's padding for the vertices).
        unsafe {
            let scene = rtcNewScene(device.0);
            rtcSetSceneFlags(scene, RTC_SCENE_FLAG_DYNAMIC);
            rtcSetSceneBuildQuality(scene, Quality::Low as c_uint);
            let geom = rtcNewGeometry(device.0, RTC_GEOMETRY_TYPE_TRIANGLE);
            rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_REFIT);
            rtcSetSharedGeometryBuffer(
                geom,
                RTC_BUFFER_TYPE_VERTEX,
                0,
                RTC_FORMAT_FLOAT3,
                // A mutable pointer: the buffer is written in place by `update` between commits.
                vertices.as_mut_ptr().cast(),
                0,
                12,
                tris.len() * 3,
            );
            rtcSetSharedGeometryBuffer(
                geom,
                RTC_BUFFER_TYPE_INDEX,
                0,
                RTC_FORMAT_UINT3,
                indices.as_ptr().cast(),
                0,
                12,
                tris.len(),
            );
            rtcCommitGeometry(geom);
            rtcAttachGeometry(scene, geom);
            rtcCommitScene(scene);
            assert_eq!(rtcGetDeviceError(device.0), 0, "Embree reported an error");
            Self {
                scene,
                geom,
                vertices,
                _indices: indices,
                _device: device,
            }
        }
    }

    /// Overwrites the shared vertices with `tris` (same count; not a refit yet).
    pub fn set_vertices(&mut self, tris: &[[Vec3; 3]]) {
        for (i, t) in tris.iter().enumerate().take(self.vertices.len() / 9) {
            for (j, p) in t.iter().enumerate() {
                self.vertices[i * 9 + j * 3..i * 9 + j * 3 + 3].copy_from_slice(&p.to_array());
            }
        }
    }

    /// Refits Embree's BVH to the shared vertices: the buffer marked updated, the geometry and
    /// the scene committed.
    pub fn refit(&mut self) {
        // SAFETY: a live geometry and scene; the vertex buffer is still the one shared at setup.
        unsafe {
            rtcUpdateGeometryBuffer(self.geom, RTC_BUFFER_TYPE_VERTEX, 0);
            rtcCommitGeometry(self.geom);
            rtcCommitScene(self.scene);
        }
    }

    /// Closest hit: `(t, primitive)`.
    pub fn intersect1(&self, r: &Ray) -> Option<(f32, u32)> {
        intersect1(self.scene, r, u32::MAX)
    }
}

impl Drop for RefitScene<'_> {
    fn drop(&mut self) {
        // SAFETY: created by rtcNewGeometry/rtcNewScene, each released once, before the shared
        // buffers they read (dropped after this).
        unsafe {
            rtcReleaseGeometry(self.geom);
            rtcReleaseScene(self.scene);
        }
    }
}

// ---- rtcBuildBVH: Embree's builder over boxes, the tree handed back through callbacks ----

#[repr(C)]
struct Inner {
    is_leaf: u32,
    bounds: [RTCBounds; 2],
    children: [*mut c_void; 2],
}

#[repr(C)]
struct Leaf {
    is_leaf: u32,
    count: u32,
}

extern "C" fn create_node(alloc: RTCThreadLocalAllocator, count: c_uint, _: *mut c_void) -> *mut c_void {
    debug_assert_eq!(count, 2);
    // SAFETY: Embree's allocator returns memory of the requested size and alignment, owned by the BVH.
    unsafe {
        let p = rtcThreadLocalAlloc(alloc, std::mem::size_of::<Inner>(), 16) as *mut Inner;
        p.write(Inner {
            is_leaf: 0,
            bounds: [std::mem::zeroed(); 2],
            children: [null_mut(); 2],
        });
        p as *mut c_void
    }
}

extern "C" fn set_children(node: *mut c_void, children: *mut *mut c_void, count: c_uint, _: *mut c_void) {
    // SAFETY: `node` is an `Inner` we created; Embree passes `count` (2) child pointers.
    unsafe {
        let n = &mut *(node as *mut Inner);
        for i in 0..count.min(2) as usize {
            n.children[i] = *children.add(i);
        }
    }
}

extern "C" fn set_bounds(node: *mut c_void, bounds: *const *const RTCBounds, count: c_uint, _: *mut c_void) {
    // SAFETY: as in `set_children`, with `count` bounds pointers.
    unsafe {
        let n = &mut *(node as *mut Inner);
        for i in 0..count.min(2) as usize {
            n.bounds[i] = **bounds.add(i);
        }
    }
}

extern "C" fn create_leaf(
    alloc: RTCThreadLocalAllocator,
    _prims: *const RTCBuildPrimitive,
    count: usize,
    _: *mut c_void,
) -> *mut c_void {
    // SAFETY: as in `create_node`.
    unsafe {
        let p = rtcThreadLocalAlloc(alloc, std::mem::size_of::<Leaf>(), 16) as *mut Leaf;
        p.write(Leaf {
            is_leaf: 1,
            count: count as u32,
        });
        p as *mut c_void
    }
}

/// What `rtcBuildBVH` made: its SAH cost (same normalisation as strahl: node and leaf costs
/// weighted by surface area over the root's), nodes and leaves.
#[derive(Clone, Copy, Debug)]
pub struct BuiltBvh {
    /// SAH cost with the given `C_T`, `C_I`.
    pub sah: f64,
    /// Interior nodes.
    pub inner: usize,
    /// Leaves.
    pub leaves: usize,
}

fn half_area(b: &RTCBounds) -> f64 {
    let d = [0, 1, 2].map(|a| (b.upper[a] - b.lower[a]).max(0.0) as f64);
    d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
}

/// Builds a binary BVH over `boxes` with Embree's `rtcBuildBVH` (`quality`, leaves of 1 to
/// `max_leaf` primitives, costs `c_t`, `c_i`), returning its SAH cost. `boxes` must be valid.
pub fn build_bvh(device: &Device, boxes: &[Aabb], quality: Quality, max_leaf: u32, c_t: f32, c_i: f32) -> BuiltBvh {
    let mut prims: Vec<RTCBuildPrimitive> = boxes
        .iter()
        .enumerate()
        .map(|(i, b)| RTCBuildPrimitive {
            lower: b.min.to_array(),
            geom_id: 0,
            upper: b.max.to_array(),
            prim_id: i as u32,
        })
        .collect();
    let count = prims.len();
    // Spatial splits (HIGH) need spare capacity; we do not provide a split callback, so keep it at count.
    prims.reserve(count);
    // SAFETY: `prims` outlives the build; the callbacks only touch memory from Embree's allocator;
    // the BVH (and its nodes) is released after the tree is read.
    unsafe {
        let bvh = rtcNewBVH(device.0);
        let args = RTCBuildArguments {
            byte_size: std::mem::size_of::<RTCBuildArguments>(),
            build_quality: quality as c_uint,
            build_flags: 0,
            max_branching_factor: 2,
            max_depth: 1024,
            sah_block_size: 1,
            min_leaf_size: 1,
            max_leaf_size: max_leaf,
            traversal_cost: c_t,
            intersection_cost: c_i,
            bvh,
            primitives: prims.as_mut_ptr(),
            primitive_count: count,
            primitive_array_capacity: prims.capacity(),
            create_node: Some(create_node),
            set_node_children: Some(set_children),
            set_node_bounds: Some(set_bounds),
            create_leaf: Some(create_leaf),
            split_primitive: null(),
            build_progress: null(),
            user_ptr: null_mut(),
        };
        let root = rtcBuildBVH(&args);
        let root_box = boxes.iter().fold(Aabb::EMPTY, |a, b| a.union(b));
        let root_area = {
            let b = RTCBounds {
                lower: root_box.min.to_array(),
                align0: 0.0,
                upper: root_box.max.to_array(),
                align1: 0.0,
            };
            half_area(&b).max(f64::MIN_POSITIVE)
        };
        let mut out = BuiltBvh {
            sah: 0.0,
            inner: 0,
            leaves: 0,
        };
        // (node, half area of its box)
        let mut stack: Vec<(*mut c_void, f64)> = vec![(root, root_area)];
        while let Some((n, area)) = stack.pop() {
            if n.is_null() {
                continue;
            }
            if *(n as *const u32) == 1 {
                let leaf = &*(n as *const Leaf);
                out.leaves += 1;
                out.sah += c_i as f64 * leaf.count as f64 * area / root_area;
            } else {
                let inner = &*(n as *const Inner);
                out.inner += 1;
                out.sah += c_t as f64 * area / root_area;
                for i in 0..2 {
                    stack.push((inner.children[i], half_area(&inner.bounds[i])));
                }
            }
        }
        rtcReleaseBVH(bvh);
        out
    }
}

// ---- rtcBuildBVH, the whole tree kept: leaves remember their primitives, for conversion ----

/// A leaf of a [`BuiltTree`]: `count` primitive ids follow the header in Embree's node memory.
#[repr(C)]
struct IdLeaf {
    is_leaf: u32,
    count: u32,
    // `count` u32 primitive ids follow.
}

extern "C" fn create_id_leaf(
    alloc: RTCThreadLocalAllocator,
    prims: *const RTCBuildPrimitive,
    count: usize,
    _: *mut c_void,
) -> *mut c_void {
    let bytes = std::mem::size_of::<IdLeaf>() + count * std::mem::size_of::<u32>();
    // SAFETY: Embree's allocator returns `bytes` bytes aligned to 16, owned by the BVH; Embree
    // passes `count` valid build primitives.
    unsafe {
        let p = rtcThreadLocalAlloc(alloc, bytes, 16) as *mut IdLeaf;
        p.write(IdLeaf {
            is_leaf: 1,
            count: count as u32,
        });
        let ids = p.add(1) as *mut u32;
        for i in 0..count {
            ids.add(i).write((*prims.add(i)).prim_id);
        }
        p as *mut c_void
    }
}

type SplitPrimitive = extern "C" fn(*const RTCBuildPrimitive, c_uint, f32, *mut RTCBounds, *mut RTCBounds, *mut c_void);

/// Embree's `splitPrimitive` callback: the reference's triangle (`user` points to the `&[[Vec3;
/// 3]]` of [`BuiltTree::build_split`]) clipped at `position` on `dimension`, within the
/// reference's box.
extern "C" fn split_triangle(
    prim: *const RTCBuildPrimitive,
    dimension: c_uint,
    position: f32,
    left: *mut RTCBounds,
    right: *mut RTCBounds,
    user: *mut c_void,
) {
    // SAFETY: Embree passes a valid primitive and two bounds to write; `user` is the slice
    // reference `build_split` set up, alive for the build.
    unsafe {
        let tris: &[[Vec3; 3]] = *(user as *const &[[Vec3; 3]]);
        let p = &*prim;
        let within = Aabb::new(Vec3::from_array(p.lower), Vec3::from_array(p.upper));
        let (l, r) = match tris.get(p.prim_id as usize) {
            Some(t) => strahl::build::clip_triangle(t, &within, dimension as usize, position),
            None => (Aabb::EMPTY, Aabb::EMPTY),
        };
        // Embree counts the reference on both sides: a side without a part of the triangle gets
        // the reference's box cut to that side (never empty; tested for nothing, conservative).
        let d = (dimension as usize).min(2);
        let side = |b: Aabb, left: bool| {
            if !b.is_empty() {
                return b;
            }
            let mut c = within;
            if left {
                c.max[d] = c.max[d].min(position).max(c.min[d]);
            } else {
                c.min[d] = c.min[d].max(position).min(c.max[d]);
            }
            c
        };
        let (l, r) = (side(l, true), side(r, false));
        for (out, b) in [(left, l), (right, r)] {
            (*out).lower = b.min.to_array();
            (*out).upper = b.max.to_array();
        }
    }
}

fn to_aabb(b: &RTCBounds) -> Aabb {
    Aabb::new(Vec3::from_array(b.lower), Vec3::from_array(b.upper))
}

/// Settings of one [`BuiltTree::build`] (`rtcBuildBVH`'s arguments that matter for quality).
#[derive(Clone, Copy, Debug)]
pub struct TreeSettings {
    /// Build quality. `rtcBuildBVH` runs its Morton builder for `Low` and its binned SAH builder
    /// for `Medium`; `High` means spatial splits, which need a split callback (given only by
    /// [`BuiltTree::build_split`]), so in [`BuiltTree::build`] `High` runs the binned SAH builder
    /// too.
    pub quality: Quality,
    /// Largest leaf (at most 32, `RTC_BUILD_MAX_PRIMITIVES_PER_LEAF`).
    pub max_leaf: u32,
    /// `C_T`.
    pub traversal_cost: f32,
    /// `C_I`.
    pub intersection_cost: f32,
}

/// A binary BVH built by `rtcBuildBVH` (branching factor 2, one thread), kept in Embree's node
/// memory with each leaf's primitive ids, so that it can be walked with [`root`](Self::root) and
/// [`node`](Self::node) and converted to another layout. Rebuilding the same `BuiltTree` reuses
/// Embree's BVH object (and its node allocator) and the primitive array; the tree is released on
/// drop.
pub struct BuiltTree<'d> {
    bvh: RTCBVH,
    prims: Vec<RTCBuildPrimitive>,
    root: *mut c_void,
    bounds: Aabb,
    _device: &'d Device,
}

/// A node of a [`BuiltTree`] (valid while the tree is neither rebuilt nor dropped).
#[derive(Clone, Copy)]
pub struct TreeNode<'t>(*const c_void, std::marker::PhantomData<&'t ()>);

/// What a [`TreeNode`] is.
pub enum TreeNodeKind<'t> {
    /// A leaf and its primitive ids (indices into the boxes given to the build).
    Leaf(&'t [u32]),
    /// An interior node: its two children with their boxes.
    Inner([(Aabb, TreeNode<'t>); 2]),
}

impl<'d> BuiltTree<'d> {
    /// An empty tree on `device` (one `rtcNewBVH`).
    pub fn new(device: &'d Device) -> Self {
        // SAFETY: a live device; Embree returns null on failure (checked).
        let bvh = unsafe { rtcNewBVH(device.0) };
        assert!(!bvh.is_null(), "rtcNewBVH failed");
        Self {
            bvh,
            prims: Vec::new(),
            root: null_mut(),
            bounds: Aabb::EMPTY,
            _device: device,
        }
    }

    /// (Re)builds the tree over `boxes` (all valid) with `s`; the previous tree is gone.
    pub fn build(&mut self, boxes: &[Aabb], s: &TreeSettings) {
        self.build_with(boxes, None, s);
    }

    /// [`build`](Self::build) with spatial splits (`s.quality` should be `High`, where
    /// `rtcBuildBVH` runs its spatial-split builder): `boxes` are `tris`' boxes, and Embree's
    /// `splitPrimitive` callback clips `tris[prim_id]` with `strahl::build::clip_triangle`, with
    /// room for one split reference per primitive (up to 2 references per triangle). Leaves may
    /// then share a triangle.
    pub fn build_split(&mut self, boxes: &[Aabb], tris: &[[Vec3; 3]], s: &TreeSettings) {
        self.build_with(boxes, Some(tris), s);
    }

    /// [`build`](Self::build), or with `split` (the triangles) [`build_split`](Self::build_split).
    fn build_with(&mut self, boxes: &[Aabb], split: Option<&[[Vec3; 3]]>, s: &TreeSettings) {
        self.prims.clear();
        if split.is_some() {
            self.prims.reserve(2 * boxes.len());
        }
        let mut bounds = Aabb::EMPTY;
        self.prims.extend(boxes.iter().enumerate().map(|(i, b)| {
            bounds = bounds.union(b);
            RTCBuildPrimitive {
                lower: b.min.to_array(),
                geom_id: 0,
                upper: b.max.to_array(),
                prim_id: i as u32,
            }
        }));
        self.bounds = bounds;
        let mut user = split.unwrap_or(&[]);
        let args = RTCBuildArguments {
            byte_size: std::mem::size_of::<RTCBuildArguments>(),
            build_quality: s.quality as c_uint,
            build_flags: 0,
            max_branching_factor: 2,
            max_depth: 1024,
            sah_block_size: 1,
            min_leaf_size: 1,
            max_leaf_size: s.max_leaf.clamp(1, 32),
            traversal_cost: s.traversal_cost,
            intersection_cost: s.intersection_cost,
            bvh: self.bvh,
            primitives: self.prims.as_mut_ptr(),
            primitive_count: self.prims.len(),
            primitive_array_capacity: if split.is_some() {
                self.prims.capacity()
            } else {
                self.prims.len()
            },
            create_node: Some(create_node),
            set_node_children: Some(set_children),
            set_node_bounds: Some(set_bounds),
            create_leaf: Some(create_id_leaf),
            split_primitive: if split.is_some() {
                split_triangle as SplitPrimitive as *const c_void
            } else {
                null()
            },
            build_progress: null(),
            user_ptr: (&mut user as *mut &[[Vec3; 3]]).cast(),
        };
        // SAFETY: `prims` lives (unmoved) for the whole call; the callbacks only write memory
        // from Embree's allocator, which the BVH object owns until the next build or release.
        // With splits, Embree writes split references into the array's spare capacity
        // (allocated, never read through the `Vec`), and `user` (read by `split_triangle`)
        // lives for the whole call.
        self.root = if self.prims.is_empty() {
            null_mut()
        } else {
            unsafe { rtcBuildBVH(&args) }
        };
    }

    /// The root and the box of all primitives, `None` for an empty tree (or a failed build).
    pub fn root(&self) -> Option<(Aabb, TreeNode<'_>)> {
        (!self.root.is_null()).then_some((self.bounds, TreeNode(self.root, std::marker::PhantomData)))
    }

    /// What node `n` of this tree is.
    pub fn node<'t>(&'t self, n: TreeNode<'t>) -> TreeNodeKind<'t> {
        // SAFETY: `n` came from this tree (the lifetime ties it to `&self`, so the tree has not
        // been rebuilt); every node starts with its `is_leaf` word, written by our callbacks.
        unsafe {
            if *(n.0 as *const u32) == 1 {
                let leaf = n.0 as *const IdLeaf;
                let ids = leaf.add(1) as *const u32;
                TreeNodeKind::Leaf(std::slice::from_raw_parts(ids, (*leaf).count as usize))
            } else {
                let inner = &*(n.0 as *const Inner);
                TreeNodeKind::Inner([0, 1].map(|i| {
                    (
                        to_aabb(&inner.bounds[i]),
                        TreeNode(inner.children[i], std::marker::PhantomData),
                    )
                }))
            }
        }
    }
}

impl Drop for BuiltTree<'_> {
    fn drop(&mut self) {
        // SAFETY: created by rtcNewBVH, released once; no TreeNode outlives `self`.
        unsafe { rtcReleaseBVH(self.bvh) }
    }
}

// ---- rtcIntersect16: sixteen rays as one packet (for benches/packet.rs) ----

#[repr(C, align(64))]
struct RTCRayHit16 {
    org_x: [f32; 16],
    org_y: [f32; 16],
    org_z: [f32; 16],
    tnear: [f32; 16],
    dir_x: [f32; 16],
    dir_y: [f32; 16],
    dir_z: [f32; 16],
    time: [f32; 16],
    tfar: [f32; 16],
    mask: [c_uint; 16],
    id: [c_uint; 16],
    flags: [c_uint; 16],
    ng_x: [f32; 16],
    ng_y: [f32; 16],
    ng_z: [f32; 16],
    u: [f32; 16],
    v: [f32; 16],
    prim_id: [c_uint; 16],
    geom_id: [c_uint; 16],
    inst_id: [c_uint; 16],
}

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcIntersect16(valid: *const i32, scene: RTCScene, ctx: *mut RTCIntersectContext, rayhit: *mut RTCRayHit16);
}

impl Scene<'_> {
    /// Sixteen rays as one packet: `(t, primitive)` per lane.
    pub fn intersect16(&self, rays: &[Ray]) -> [Option<(f32, u32)>; 16] {
        let mut valid = [0i32; 16];
        // SAFETY: an all-zero RTCRayHit16 is a valid value (plain floats and integers).
        let mut rh: RTCRayHit16 = unsafe { std::mem::zeroed() };
        for (i, r) in rays.iter().take(16).enumerate() {
            valid[i] = -1;
            [rh.org_x[i], rh.org_y[i], rh.org_z[i]] = r.origin.to_array();
            [rh.dir_x[i], rh.dir_y[i], rh.dir_z[i]] = r.direction.to_array();
            rh.tnear[i] = r.tmin;
            rh.tfar[i] = r.tmax;
            rh.mask[i] = u32::MAX;
            rh.geom_id[i] = RTC_INVALID_GEOMETRY_ID;
        }
        let mut ctx = context();
        ctx.flags = 1; // coherent
        // SAFETY: `valid` has 16 ints, `rh` is 64-byte aligned and initialised.
        unsafe { rtcIntersect16(valid.as_ptr(), self.scene, &mut ctx, &mut rh) };
        std::array::from_fn(|i| (rh.geom_id[i] != RTC_INVALID_GEOMETRY_ID).then_some((rh.tfar[i], rh.prim_id[i])))
    }
}
