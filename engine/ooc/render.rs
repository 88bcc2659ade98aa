//! The path tracer: in-core (every point loaded, each path traced alone) and out-of-core
//! (batched ray traversal under a memory budget, optionally culled by the SVDAG proxies).
//!
//! Both run the same per-ray steps (`Tracer::advance`, `intersect_point`), so the images are
//! bit-identical: a ray visits the batching points its top-level BVH traversal finds in order of
//! `(entry distance, point id)` while the entry is not behind its closest hit so far; the
//! batched renderer only interleaves rays differently, and a proxy only removes points the ray
//! cannot hit. Each path's radiance lands in its own `(pixel, sample)` slot; pixels sum their
//! slots in sample order at the end. Random numbers are a hash of (pixel, sample, bounce, seed).

use std::time::Instant;

use indicatif::ProgressBar;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::format::{OocScene, TRI_BYTES};
use super::geom::{facing_normal, Aabb, Bvh, Node, RayPre, Tri};
use super::prepare::mix64;
use super::proxy::{Grid, ProxySet};
use super::OocError;

/// Diffuse reflectance of every surface.
const ALBEDO: f32 = 0.7;

/// Options of a render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Paths per pixel.
    pub spp: u32,
    /// Seed of the random numbers.
    pub seed: u64,
    /// Diffuse bounces after the camera ray.
    pub max_bounces: u32,
    /// Bytes for geometry and proxies (out-of-core only).
    pub memory_budget: u64,
    /// Rays in flight (out-of-core only).
    pub rays_in_flight: usize,
    /// Out-of-core only: a ray whose next point is not resident first visits the resident
    /// points after it, and a chosen point's rays are traced again before it is loaded
    /// (`Tracer::speculate`); off: the batched traversal of Pharr et al. as published.
    pub lookahead: bool,
    /// Out-of-core only: which resident point the cache evicts to make room.
    pub eviction: Eviction,
    /// Out-of-core only: which point's queue is loaded next.
    pub schedule: Schedule,
    /// Camera position; default: in front of and above the scene.
    pub eye: Option<[f32; 3]>,
    /// Point looked at; default: the centre of the scene.
    pub target: Option<[f32; 3]>,
    /// Vertical field of view in degrees.
    pub fov_degrees: f32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 256,
            height: 256,
            spp: 4,
            seed: 0,
            max_bounces: 3,
            memory_budget: 1 << 30,
            rays_in_flight: 1 << 16,
            lookahead: true,
            eviction: Eviction::default(),
            schedule: Schedule::default(),
            eye: None,
            target: None,
            fov_degrees: 50.0,
        }
    }
}

/// Which resident point the out-of-core cache evicts when a load needs room. Never changes the
/// image, only which points are read again later.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Eviction {
    /// The least recently used point.
    Lru,
    /// The point the fewest queued rays will still visit (its *demand*: rays waiting at other
    /// points that have it later on their list, proxy-tested), least recently used on ties: a
    /// Belady-like choice from the queues' contents.
    #[default]
    Demand,
}

/// Which point's queue the out-of-core renderer loads next. Never changes the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Schedule {
    /// The most queued rays (Pharr et al.).
    Fullest,
    /// The most queued rays net of its demand (rays queued elsewhere that will still arrive):
    /// a point whose rays are still coming is deferred, so that one load serves them all.
    #[default]
    Net,
}

impl Schedule {
    /// The policy's name, as `--schedule` and the report spell it.
    pub fn name(self) -> &'static str {
        match self {
            Schedule::Fullest => "fullest",
            Schedule::Net => "net",
        }
    }

    /// The point to load among `(point, queued rays, demand)` of the non-empty queues: the
    /// largest `queued` (fullest) or `queued - demand` (net); the lowest id on ties.
    pub fn choose(self, queues: impl IntoIterator<Item = (u32, u32, u32)>) -> Option<u32> {
        let score = |&(_, q, d): &(u32, u32, u32)| match self {
            Schedule::Fullest => i64::from(q),
            Schedule::Net => i64::from(q) - i64::from(d),
        };
        queues
            .into_iter()
            .max_by(|a, b| score(a).cmp(&score(b)).then(b.0.cmp(&a.0)))
            .map(|c| c.0)
    }
}

/// A resident point as the eviction choice sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resident {
    /// Point id.
    pub id: u32,
    /// Cache clock of its last use (larger: more recent).
    pub last_used: u64,
    /// Queued rays that will still visit it.
    pub demand: u32,
}

impl Eviction {
    /// The policy's name, as `--eviction` and the report spell it.
    pub fn name(self) -> &'static str {
        match self {
            Eviction::Lru => "lru",
            Eviction::Demand => "demand",
        }
    }

    /// The point to evict among `resident`: the smallest `last_used` (LRU) or the smallest
    /// `(demand, last_used)` (demand); the lowest id on ties. `None` when nothing is resident.
    pub fn victim(self, resident: impl IntoIterator<Item = Resident>) -> Option<u32> {
        let key = |r: &Resident| match self {
            Eviction::Lru => (0, r.last_used, r.id),
            Eviction::Demand => (r.demand, r.last_used, r.id),
        };
        resident.into_iter().min_by_key(key).map(|r| r.id)
    }
}

/// Counters of a render (the `--report` JSON).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RenderStats {
    /// "in-core" or "out-of-core".
    pub mode: String,
    /// Whether proxies culled the queueing.
    pub proxies: bool,
    /// Eviction policy of the cache (out-of-core).
    pub eviction: Option<Eviction>,
    /// Which queue is loaded next (out-of-core).
    pub schedule: Option<Schedule>,
    /// Proxy resolution (0 without proxies).
    pub proxy_resolution: u32,
    /// Bytes the proxies take in memory.
    pub proxy_bytes: u64,
    /// Memory budget for geometry plus proxies.
    pub memory_budget: u64,
    /// Bytes of geometry read from `geometry.bin`.
    pub disk_bytes_read: u64,
    /// Times a point's queue was processed.
    pub batching_events: u64,
    /// Batching events in which no queued ray hit a triangle of the point (the load was of no
    /// use to any ray: what a perfect proxy would avoid).
    pub empty_batches: u64,
    /// Ray visits of points (a ray intersected with a loaded point).
    pub ray_visits: u64,
    /// Ray visits that found the ray's closest hit so far in the point.
    pub ray_visits_hit: u64,
    /// Ray visits made at once, outside a batching event, because the ray's next point was
    /// resident in the cache.
    pub resident_visits: u64,
    /// Ray visits of resident points ahead of the ray's order, made while its next point was not
    /// resident (their closest hit may let the proxy of that point cull it).
    pub speculative_visits: u64,
    /// Rays taken out of a point's queue when it was chosen and traced again against the points
    /// resident by then, before the point was loaded.
    pub requeued_rays: u64,
    /// Rays that left the chosen point's queue that way (the point was no longer needed).
    pub requeue_culls: u64,
    /// Distinct points read from disk (`cache_misses` minus this: reloads of evicted points).
    pub points_loaded: u64,
    /// Batching events whose point was already in the cache.
    pub cache_hits: u64,
    /// Batching events that loaded their point from disk.
    pub cache_misses: u64,
    /// Largest bytes of geometry and BVHs held at once.
    pub peak_cache_bytes: u64,
    /// Times a ray was not queued at a point because it missed the point's proxy.
    pub proxy_culls: u64,
    /// Rays traced (camera rays and bounces).
    pub rays: u64,
    /// Paths traced (width * height * spp).
    pub paths: u64,
    /// Wall time of the render in seconds (opening the scene excluded).
    pub wall_s: f64,
    /// Rays per second of wall time.
    pub rays_per_s: f64,
    /// Bytes of the scene files.
    pub scene_file_bytes: u64,
}

/// A rendered image: per pixel the mean radiance (linear RGB).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Rows top to bottom.
    pub pixels: Vec<[f32; 3]>,
}

impl Image {
    /// sRGB RGBA8 bytes (values clamped to [0, 1]).
    pub fn to_rgba8(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.pixels.len() * 4);
        for p in &self.pixels {
            for c in p {
                let v = crate::color::linear_to_srgb(c.clamp(0.0, 1.0));
                out.push((v * 255.0 + 0.5) as u8);
            }
            out.push(255);
        }
        out
    }
}

/// A point's triangles in BVH order with their BVH, as held in the cache.
pub struct LoadedPoint {
    tris: Vec<Tri>,
    ids: Vec<u32>,
    nodes: Vec<Node>,
}

impl LoadedPoint {
    /// Builds the bottom-level BVH over a point's triangles.
    pub fn build(tris: Vec<Tri>) -> LoadedPoint {
        let boxes: Vec<Aabb> = tris.iter().map(Aabb::of_tri).collect();
        let bvh = Bvh::build(&boxes);
        let ordered = bvh.order.iter().map(|&i| tris[i as usize]).collect();
        LoadedPoint {
            tris: ordered,
            ids: bvh.order,
            nodes: bvh.nodes,
        }
    }

    /// Bytes held in memory.
    pub fn bytes(&self) -> u64 {
        self.tris.len() as u64 * TRI_BYTES
            + self.ids.len() as u64 * 4
            + (self.nodes.len() * std::mem::size_of::<Node>()) as u64
    }
}

/// The closest hit of a ray so far.
#[derive(Clone, Copy, Debug)]
struct Best {
    t: f32,
    point: u32,
    tri: u32,
    normal: [f32; 3],
}

const NO_HIT: Best = Best {
    t: f32::INFINITY,
    point: u32::MAX,
    tri: u32::MAX,
    normal: [0.0; 3],
};

/// Points a ray may visit ahead of its order (see [`Tracer::speculate`]).
const SPECULATIVE: usize = 6;

/// The largest entry distance at which a point can still hold a hit that beats `best`: `best`
/// widened by a relative margin far above the f32 rounding of the slab and triangle tests, so
/// the closest hit found does not depend on the order in which the points are visited.
#[inline]
fn reach(best: f32) -> f32 {
    best + best * 1e-4
}

/// One path's state between batching events.
#[derive(Clone, Copy, Debug)]
struct PathState {
    /// `pixel * spp + sample`.
    slot: u32,
    bounce: u32,
    ray: RayPre,
    throughput: f32,
    best: Best,
    /// `(entry distance, point)` of the last point visited in order by the current ray.
    last: Option<(f32, u32)>,
    /// `(entry distance, point)` of the point the ray waits at.
    wait: (f32, u32),
    /// Points already visited ahead of order by the current ray (skipped when reached).
    ahead: [u32; SPECULATIVE],
    /// Entries used in `ahead`.
    n_ahead: u8,
}

impl PathState {
    fn visited_ahead(&self, id: u32) -> bool {
        self.ahead[..self.n_ahead as usize].contains(&id)
    }
}

/// Intersects a ray with a loaded point, keeping the smallest `(t, point, triangle)`.
fn intersect_point(p: &LoadedPoint, point: u32, ray: &RayPre, best: &mut Best) {
    if p.nodes.is_empty() {
        return;
    }
    let mut stack = [0u32; 64];
    let mut sp = 1;
    while sp > 0 {
        sp -= 1;
        let node = &p.nodes[stack[sp] as usize];
        let (t0, t1) = ray.slab(&node.bounds);
        if t0 > t1 || t0 > reach(best.t) {
            continue;
        }
        if node.count > 0 {
            for i in node.first..node.first + node.count {
                let tri = &p.tris[i as usize];
                if let Some(t) = ray.intersect(tri) {
                    let id = p.ids[i as usize];
                    if (t, point, id) < (best.t, best.point, best.tri) {
                        *best = Best {
                            t,
                            point,
                            tri: id,
                            normal: facing_normal(tri, ray.dir),
                        };
                    }
                }
            }
        } else if sp + 2 <= stack.len() {
            stack[sp] = node.first + 1;
            stack[sp + 1] = node.first;
            sp += 2;
        }
    }
}

/// What one advance of a path ends in.
enum Advance {
    /// The path's ray waits at this point.
    Queued(PathState, u32),
    /// The path is finished with this radiance.
    Done(u32, [f32; 3]),
}

/// Per-advance counters.
#[derive(Default, Clone, Copy)]
struct StepCount {
    rays: u64,
    culls: u64,
    /// 1 when the ray was intersected with the loaded point.
    visits: u64,
    /// 1 when that gave the ray's closest hit so far.
    hits: u64,
    /// 1 when the ray's first visit, at the batch's point, gave its closest hit so far.
    batch_hits: u64,
    /// Visits of resident points outside a batching event.
    resident: u64,
    /// Visits of resident points ahead of the ray's order.
    ahead: u64,
}

/// Everything the per-ray steps read: camera, top-level BVH, optional proxies.
struct Tracer<'a> {
    scene: &'a OocScene,
    top: Bvh,
    proxies: Option<(&'a ProxySet, Vec<Grid>)>,
    opts: &'a RenderOptions,
    eye: [f32; 3],
    forward: [f32; 3],
    right: [f32; 3],
    up: [f32; 3],
    eps: f32,
}

fn normalize(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if l > 0.0 {
        [v[0] / l, v[1] / l, v[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    }
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

impl<'a> Tracer<'a> {
    fn new(
        scene: &'a OocScene,
        proxies: Option<&'a ProxySet>,
        opts: &'a RenderOptions,
    ) -> Result<Tracer<'a>, OocError> {
        if opts.width == 0 || opts.height == 0 || opts.spp == 0 {
            return Err(OocError::Invalid(
                "image size and spp must be positive".into(),
            ));
        }
        let paths = opts.width as u64 * opts.height as u64 * opts.spp as u64;
        if paths > u32::MAX as u64 {
            return Err(OocError::Invalid(format!(
                "{paths} paths: at most 2^32 - 1"
            )));
        }
        let boxes: Vec<Aabb> = scene.points.iter().map(|p| p.bounds).collect();
        let top = Bvh::build(&boxes);
        let proxies = proxies.map(|set| {
            let grids = scene
                .points
                .iter()
                .map(|p| Grid::new(&p.bounds, set.resolution))
                .collect();
            (set, grids)
        });
        let b = &scene.bounds;
        let c = b.center();
        let e = [0, 1, 2].map(|k| b.hi[k] - b.lo[k]);
        let diag = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt().max(1e-6);
        let horizontal = e[0].max(e[2]);
        let eye = opts.eye.unwrap_or([
            c[0],
            b.hi[1] + 0.15 * horizontal,
            b.lo[2] - 0.15 * e[2].max(0.3 * diag),
        ]);
        let target = opts.target.unwrap_or(c);
        let forward = normalize([target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]]);
        let mut right = cross(forward, [0.0, 1.0, 0.0]);
        if right == [0.0; 3] {
            right = [1.0, 0.0, 0.0];
        }
        let right = normalize(right);
        let up = cross(right, forward);
        let max_coord = (0..3)
            .map(|k| b.lo[k].abs().max(b.hi[k].abs()))
            .fold(0.0f32, f32::max);
        Ok(Tracer {
            scene,
            top,
            proxies,
            opts,
            eye,
            forward,
            right,
            up,
            eps: 1e-5 * diag + 1e-6 * max_coord,
        })
    }

    fn paths(&self) -> u32 {
        self.opts.width * self.opts.height * self.opts.spp
    }

    /// A uniform number in [0, 1) keyed by (pixel, sample, bounce, seed) and a dimension.
    fn random(&self, slot: u32, bounce: u32, dim: u32) -> f32 {
        let spp = self.opts.spp;
        let key = ((slot / spp) as u64) << 32 | (slot % spp) as u64;
        let h = mix64(self.opts.seed ^ mix64(key ^ mix64(((bounce as u64) << 8) | dim as u64)));
        (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    fn camera_path(&self, slot: u32) -> PathState {
        let o = self.opts;
        let pixel = slot / o.spp;
        let (px, py) = (pixel % o.width, pixel / o.width);
        let tan = (o.fov_degrees.to_radians() * 0.5).tan();
        let aspect = o.width as f32 / o.height as f32;
        let x = ((px as f32 + self.random(slot, 0, 0)) / o.width as f32 * 2.0 - 1.0) * tan * aspect;
        let y = (1.0 - (py as f32 + self.random(slot, 0, 1)) / o.height as f32 * 2.0) * tan;
        let dir =
            normalize([0, 1, 2].map(|k| self.forward[k] + x * self.right[k] + y * self.up[k]));
        PathState {
            slot,
            bounce: 0,
            ray: RayPre::new(self.eye, dir),
            throughput: 1.0,
            best: NO_HIT,
            last: None,
            wait: (0.0, u32::MAX),
            ahead: [u32::MAX; SPECULATIVE],
            n_ahead: 0,
        }
    }

    /// The points the ray may still visit in order, as `(entry, id, exit)` sorted by
    /// `(entry, id)`: those after `last` whose bounds it enters within [`reach`] of its closest
    /// hit, less those it visited ahead of order.
    fn candidates(&self, path: &PathState) -> Vec<(f32, u32, f32)> {
        let ray = &path.ray;
        let limit = reach(path.best.t);
        let nodes = &self.top.nodes;
        let mut found: Vec<(f32, u32, f32)> = Vec::new();
        if nodes.is_empty() {
            return found;
        }
        let mut stack = vec![0u32];
        let after = |t: f32, id: u32| match path.last {
            None => true,
            Some((lt, lid)) => t > lt || (t == lt && id > lid),
        };
        while let Some(n) = stack.pop() {
            let node = &nodes[n as usize];
            let (t0, t1) = ray.slab(&node.bounds);
            if t0 > t1 || t0 > limit || path.last.is_some_and(|(lt, _)| t1 < lt) {
                continue;
            }
            if node.count == 0 {
                stack.push(node.first + 1);
                stack.push(node.first);
                continue;
            }
            for &id in &self.top.order[node.first as usize..(node.first + node.count) as usize] {
                let (t0, t1) = ray.slab(&self.scene.points[id as usize].bounds);
                if t0 <= t1 && t0 <= limit && after(t0, id) && !path.visited_ahead(id) {
                    found.push((t0, id, t1));
                }
            }
        }
        found.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        found
    }

    /// True when the ray may hit point `id` on `[t0, min(t1, closest hit)]`: always without
    /// proxies, else when the segment touches the point's proxy.
    fn may_hit(&self, path: &PathState, (t0, id, t1): (f32, u32, f32)) -> bool {
        match &self.proxies {
            None => true,
            Some((set, grids)) => {
                let end = t1.min(path.best.t);
                set.segment_hits(
                    id,
                    &grids[id as usize],
                    path.ray.origin,
                    path.ray.dir,
                    t0,
                    end,
                )
            }
        }
    }

    /// The points a ray waiting at `path.wait` may visit after it: the later candidates whose
    /// proxy (with proxies) the segment up to its closest hit so far touches. An estimate of
    /// its future demand for the eviction choice; the ray's closest hit may still shorten it.
    fn later(&self, path: &PathState) -> Vec<u32> {
        let (wt, wid) = path.wait;
        self.candidates(path)
            .into_iter()
            .filter(|&(t, id, _)| t.total_cmp(&wt).then(id.cmp(&wid)).is_gt())
            .filter(|&c| self.may_hit(path, c))
            .map(|c| c.1)
            .collect()
    }

    /// Visits, ahead of order, the resident points among `later` (the candidates after the
    /// ray's next point, which is not resident) that the ray may still hit, so that their
    /// closest hit shortens the segment tested against the proxies of the points before them.
    /// Returns whether any was visited. The closest hit does not depend on the visit order
    /// (smallest `(t, point, triangle)`, entries compared with [`reach`]), and a visited point
    /// is not visited again, so the image is unchanged.
    fn speculate<'p>(
        &self,
        path: &mut PathState,
        later: &[(f32, u32, f32)],
        resident: &dyn Fn(u32) -> Option<&'p LoadedPoint>,
        count: &mut StepCount,
    ) -> bool {
        let mut visited = false;
        for &c in later {
            if path.n_ahead as usize == SPECULATIVE || c.0 > reach(path.best.t) {
                break;
            }
            let Some(p) = resident(c.1) else {
                continue;
            };
            if !self.may_hit(path, c) {
                continue;
            }
            let ray = path.ray;
            intersect_point(p, c.1, &ray, &mut path.best);
            path.ahead[path.n_ahead as usize] = c.1;
            path.n_ahead += 1;
            count.visits += 1;
            count.ahead += 1;
            count.hits += u64::from(path.best.point == c.1);
            visited = true;
        }
        visited
    }

    /// Radiance of the environment in direction `d` (unit): a sky gradient.
    fn environment(d: [f32; 3]) -> [f32; 3] {
        let t = 0.5 * (d[1] + 1.0);
        [1.0 - 0.5 * t, 1.0 - 0.3 * t, 1.0]
    }

    /// Runs the path until its ray must wait at a point (`path.wait`) or the path ends. With
    /// `resident`, a next point that is not resident first lets the ray visit the resident
    /// points after it ([`Tracer::speculate`]), which may cull it.
    fn advance<'p>(
        &self,
        mut path: PathState,
        resident: Option<&dyn Fn(u32) -> Option<&'p LoadedPoint>>,
        count: &mut StepCount,
    ) -> Advance {
        loop {
            let found = self.candidates(&path);
            let mut next = None;
            for (i, &c) in found.iter().enumerate() {
                if self.may_hit(&path, c) {
                    next = Some(i);
                    break;
                }
                count.culls += 1;
            }
            if let Some(i) = next {
                let (t, id, _) = found[i];
                if let Some(res) = resident {
                    if res(id).is_none() && self.speculate(&mut path, &found[i + 1..], res, count) {
                        continue;
                    }
                }
                path.wait = (t, id);
                return Advance::Queued(path, id);
            }
            let d = path.ray.dir;
            if path.best.point == u32::MAX {
                let env = Self::environment(d);
                return Advance::Done(path.slot, env.map(|c| c * path.throughput));
            }
            let n = path.best.normal;
            if path.bounce >= self.opts.max_bounces || n == [0.0; 3] {
                return Advance::Done(path.slot, [0.0; 3]);
            }
            let o = path.ray.origin;
            let t = path.best.t;
            let p = [0, 1, 2].map(|k| o[k] + t * d[k] + self.eps * n[k]);
            // Cosine-weighted direction about n (orthonormal basis of Duff et al. 2017).
            let bounce = path.bounce + 1;
            let u1 = self.random(path.slot, bounce, 0);
            let u2 = self.random(path.slot, bounce, 1);
            let sign = 1.0f32.copysign(n[2]);
            let a = -1.0 / (sign + n[2]);
            let b = n[0] * n[1] * a;
            let tx = [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]];
            let ty = [b, sign + n[1] * n[1] * a, -n[1]];
            let r = u1.sqrt();
            let phi = std::f32::consts::TAU * u2;
            let (lx, ly, lz) = (r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
            let dir = normalize([0, 1, 2].map(|k| lx * tx[k] + ly * ty[k] + lz * n[k]));
            count.rays += 1;
            path = PathState {
                slot: path.slot,
                bounce,
                ray: RayPre::new(p, dir),
                throughput: path.throughput * ALBEDO,
                best: NO_HIT,
                last: None,
                wait: (0.0, u32::MAX),
                ahead: [u32::MAX; SPECULATIVE],
                n_ahead: 0,
            };
        }
    }

    /// Sums each pixel's slots in sample order.
    fn resolve(&self, slots: &[[f32; 3]]) -> Image {
        let spp = self.opts.spp as usize;
        let pixels = slots
            .chunks_exact(spp)
            .map(|s| {
                let mut sum = [0f32; 3];
                for v in s {
                    for k in 0..3 {
                        sum[k] += v[k];
                    }
                }
                sum.map(|c| c / spp as f32)
            })
            .collect();
        Image {
            width: self.opts.width,
            height: self.opts.height,
            pixels,
        }
    }
}

/// Renders with every point loaded and each path traced alone (the reference of
/// [`render_out_of_core`]).
pub fn render_in_core(
    scene: &OocScene,
    opts: &RenderOptions,
    progress: &ProgressBar,
) -> Result<(Image, RenderStats), OocError> {
    let tracer = Tracer::new(scene, None, opts)?;
    let start = Instant::now();
    let mut disk = 0u64;
    let mut loaded = Vec::with_capacity(scene.points.len());
    for i in 0..scene.points.len() as u32 {
        loaded.push(LoadedPoint::build(scene.read_point(i)?));
        disk += scene.points[i as usize].bytes();
    }
    let cache: u64 = loaded.iter().map(LoadedPoint::bytes).sum();
    let total = tracer.paths();
    progress.set_length(total as u64);
    let results: Vec<([f32; 3], u64)> = (0..total)
        .into_par_iter()
        .map(|slot| {
            let mut count = StepCount {
                rays: 1,
                ..Default::default()
            };
            let mut path = tracer.camera_path(slot);
            loop {
                match tracer.advance(path, None, &mut count) {
                    Advance::Queued(mut p, id) => {
                        p.last = Some(p.wait);
                        intersect_point(&loaded[id as usize], id, &p.ray, &mut p.best);
                        path = p;
                    }
                    Advance::Done(_, c) => {
                        if slot % 4096 == 0 {
                            progress.inc(4096);
                        }
                        return (c, count.rays);
                    }
                }
            }
        })
        .collect();
    let rays = results.iter().map(|r| r.1).sum();
    let slots: Vec<[f32; 3]> = results.into_iter().map(|r| r.0).collect();
    let image = tracer.resolve(&slots);
    let wall = start.elapsed().as_secs_f64();
    progress.finish_and_clear();
    Ok((
        image,
        RenderStats {
            mode: "in-core".into(),
            disk_bytes_read: disk,
            cache_misses: scene.points.len() as u64,
            peak_cache_bytes: cache,
            memory_budget: opts.memory_budget,
            rays,
            paths: total as u64,
            wall_s: wall,
            rays_per_s: rays as f64 / wall.max(1e-9),
            scene_file_bytes: scene.file_bytes(),
            ..Default::default()
        },
    ))
}

/// A ray after its advance in a batch: its slot, where it ended, its counters, the resident
/// points it visited, and the points it may visit after the one it waits at.
type Advanced = (u32, Advance, StepCount, Vec<u32>, Vec<u32>);

/// Takes the rays of `queue` out of the demand counts (they leave their queue).
fn release(queue: &[u32], future: &mut [Vec<u32>], demand: &mut [u32]) {
    for &r in queue {
        for x in future[r as usize].drain(..) {
            demand[x as usize] -= 1;
        }
    }
}

/// The cache of loaded points.
struct Cache {
    eviction: Eviction,
    budget: u64,
    used: u64,
    clock: u64,
    entries: FxHashMap<u32, (LoadedPoint, u64)>,
    /// Points read at least once.
    loaded: rustc_hash::FxHashSet<u32>,
}

/// Renders with batched ray traversal: per-point ray queues, the fullest queue first, points
/// loaded into a cache of `memory_budget` bytes minus the proxies (evicting by
/// `opts.eviction`) (with `proxies`, a ray is
/// queued at a point only when it touches its proxy).
pub fn render_out_of_core(
    scene: &OocScene,
    proxies: Option<&ProxySet>,
    opts: &RenderOptions,
    progress: &ProgressBar,
) -> Result<(Image, RenderStats), OocError> {
    let proxy_bytes = proxies.map_or(0, ProxySet::bytes);
    if proxy_bytes >= opts.memory_budget {
        return Err(OocError::Invalid(format!(
            "the proxies take {proxy_bytes} bytes, not less than the memory budget {}",
            opts.memory_budget
        )));
    }
    let tracer = Tracer::new(scene, proxies, opts)?;
    let mut stats = RenderStats {
        mode: "out-of-core".into(),
        proxies: proxies.is_some(),
        eviction: Some(opts.eviction),
        schedule: Some(opts.schedule),
        proxy_resolution: proxies.map_or(0, |p| p.resolution),
        proxy_bytes,
        memory_budget: opts.memory_budget,
        scene_file_bytes: scene.file_bytes(),
        ..Default::default()
    };
    let start = Instant::now();
    let total = tracer.paths();
    progress.set_length(total as u64);
    let mut slots: Vec<[f32; 3]> = crate::safety::try_vec("path radiance slots", total as u64)?;
    slots.resize(total as usize, [0.0; 3]);
    let in_flight = opts.rays_in_flight.clamp(1, total as usize) as u32;
    let mut rays: Vec<PathState> = (0..in_flight).map(|s| tracer.camera_path(s)).collect();
    stats.rays += in_flight as u64;
    let mut next = in_flight;
    let mut queues: Vec<Vec<u32>> = vec![Vec::new(); scene.points.len()];
    // Per queued ray: the points it may visit after the one it waits at; per point: how many
    // queued rays list it (its demand; kept for `Eviction::Demand` and `Schedule::Net`).
    let mut future: Vec<Vec<u32>> = vec![Vec::new(); in_flight as usize];
    let mut demand: Vec<u32> = vec![0; scene.points.len()];
    // Per point: `cache_misses` when its queue was last traced again (see below).
    let mut checked_at: Vec<u64> = vec![u64::MAX; scene.points.len()];
    let (mut requeued, mut requeue_total, mut requeue_kept) = (None::<u32>, 0u64, 0u64);
    // True while `pending` holds the rays taken out of the queue of `requeued`.
    let mut requeue_round = false;
    let mut cache = Cache {
        eviction: opts.eviction,
        budget: opts.memory_budget - proxy_bytes,
        used: 0,
        clock: 0,
        entries: FxHashMap::default(),
        loaded: Default::default(),
    };
    // Rays to advance, with the point each must first be intersected with (the batch's point).
    let mut pending: Vec<(u32, PathState, Option<u32>)> = rays
        .iter()
        .enumerate()
        .map(|(r, p)| (r as u32, *p, None))
        .collect();
    loop {
        // Advance the rays of the last batch (intersected first) and new camera rays until each
        // waits at a point that is not in the cache or its path is done; done paths start new
        // camera rays. A ray whose next point is resident is intersected with it at once (its
        // own surface for a bounce ray, most often): the order of its visits is unchanged.
        while !pending.is_empty() {
            let entries = &cache.entries;
            let resident = |id: u32| entries.get(&id).map(|e| &e.0);
            let demand_on = opts.eviction == Eviction::Demand || opts.schedule == Schedule::Net;
            let outs: Vec<Advanced> = pending
                .par_iter()
                .map(|&(r, mut path, first)| {
                    let mut count = StepCount::default();
                    let mut used = Vec::new();
                    let mut visit = first;
                    loop {
                        if let Some(id) = visit {
                            let (p, _) = &entries[&id];
                            path.last = Some(path.wait);
                            let ray = path.ray;
                            intersect_point(p, id, &ray, &mut path.best);
                            count.visits += 1;
                            let hit = u64::from(path.best.point == id);
                            count.hits += hit;
                            if first.is_some() && used.is_empty() {
                                count.batch_hits = hit;
                            } else {
                                count.resident += 1;
                            }
                            used.push(id);
                        }
                        let before = path.n_ahead;
                        let adv = if opts.lookahead {
                            tracer.advance(path, Some(&resident), &mut count)
                        } else {
                            tracer.advance(path, None, &mut count)
                        };
                        if let Advance::Queued(p, _) = &adv {
                            // Points visited ahead (of the ray's last bounce, if it bounced).
                            let from = if p.bounce == path.bounce { before } else { 0 };
                            used.extend_from_slice(&p.ahead[from as usize..p.n_ahead as usize]);
                        }
                        match adv {
                            Advance::Queued(p, id) if entries.contains_key(&id) => {
                                path = p;
                                visit = Some(id);
                            }
                            adv => {
                                let later = match &adv {
                                    Advance::Queued(p, _) if demand_on => tracer.later(p),
                                    _ => Vec::new(),
                                };
                                return (r, adv, count, used, later);
                            }
                        }
                    }
                })
                .collect();
            let batch = pending.first().and_then(|p| p.2);
            if batch.is_some() && outs.iter().all(|o| o.2.batch_hits == 0) {
                stats.empty_batches += 1;
            }
            pending.clear();
            let mut touched = Vec::new();
            for (r, adv, count, used, later) in outs {
                stats.rays += count.rays;
                stats.proxy_culls += count.culls;
                stats.ray_visits += count.visits;
                stats.ray_visits_hit += count.hits;
                stats.resident_visits += count.resident;
                stats.speculative_visits += count.ahead;
                touched.extend(used);
                match adv {
                    Advance::Queued(path, id) => {
                        if requeue_round && requeued == Some(id) {
                            requeue_kept += 1;
                        }
                        rays[r as usize] = path;
                        queues[id as usize].push(r);
                        for &x in &later {
                            demand[x as usize] += 1;
                        }
                        future[r as usize] = later;
                    }
                    Advance::Done(slot, c) => {
                        slots[slot as usize] = c;
                        progress.inc(1);
                        if next < total {
                            let p = tracer.camera_path(next);
                            next += 1;
                            stats.rays += 1;
                            rays[r as usize] = p;
                            pending.push((r, p, None));
                        }
                    }
                }
            }
            requeue_round = false;
            touched.sort_unstable();
            touched.dedup();
            cache.touch(&touched);
        }
        if requeued.take().is_some() {
            stats.requeue_culls += requeue_total - requeue_kept;
        }
        // The point to load (`Schedule`). Queued rays wait only at points that are not resident.
        let Some(id) = opts.schedule.choose(
            queues
                .iter()
                .zip(&demand)
                .enumerate()
                .filter(|(_, (q, _))| !q.is_empty())
                .map(|(i, (q, &d))| (i as u32, q.len() as u32, d)),
        ) else {
            break;
        };
        // Before loading it, its rays are traced again against the points resident now: points
        // loaded since they were queued may hold hits that let the proxy cull this point.
        if opts.lookahead && checked_at[id as usize] != stats.cache_misses {
            checked_at[id as usize] = stats.cache_misses;
            let queue = std::mem::take(&mut queues[id as usize]);
            release(&queue, &mut future, &mut demand);
            stats.requeued_rays += queue.len() as u64;
            requeued = Some(id);
            requeue_total = queue.len() as u64;
            requeue_kept = 0;
            requeue_round = true;
            pending = queue.iter().map(|&r| (r, rays[r as usize], None)).collect();
            continue;
        }
        cache.get(scene, id, &demand, &mut stats)?;
        stats.batching_events += 1;
        let queue = std::mem::take(&mut queues[id as usize]);
        release(&queue, &mut future, &mut demand);
        pending = queue
            .iter()
            .map(|&r| (r, rays[r as usize], Some(id)))
            .collect();
    }
    let image = tracer.resolve(&slots);
    stats.paths = total as u64;
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.rays_per_s = stats.rays as f64 / stats.wall_s.max(1e-9);
    progress.finish_and_clear();
    Ok((image, stats))
}

impl Cache {
    /// Makes point `id` resident: a hit, or a load from disk evicting points by the policy
    /// (`demand`: per point, the queued rays that will visit it) until it fits.
    fn get(
        &mut self,
        scene: &OocScene,
        id: u32,
        demand: &[u32],
        stats: &mut RenderStats,
    ) -> Result<(), OocError> {
        self.clock += 1;
        if let Some(e) = self.entries.get_mut(&id) {
            e.1 = self.clock;
            stats.cache_hits += 1;
            return Ok(());
        }
        stats.cache_misses += 1;
        if self.loaded.insert(id) {
            stats.points_loaded += 1;
        }
        let entry = &scene.points[id as usize];
        let tris = scene.read_point(id)?;
        stats.disk_bytes_read += entry.bytes();
        let loaded = LoadedPoint::build(tris);
        let need = loaded.bytes();
        if need > self.budget {
            return Err(OocError::Invalid(format!(
                "point {id} needs {need} bytes with its BVH, more than the {} bytes of the budget left for geometry",
                self.budget
            )));
        }
        while self.used + need > self.budget {
            let victim = self
                .eviction
                .victim(self.entries.iter().map(|(&id, e)| Resident {
                    id,
                    last_used: e.1,
                    demand: demand[id as usize],
                }))
                .expect("something to evict while over budget");
            let (p, _) = self.entries.remove(&victim).expect("present");
            self.used -= p.bytes();
        }
        self.used += need;
        stats.peak_cache_bytes = stats.peak_cache_bytes.max(self.used);
        self.entries.insert(id, (loaded, self.clock));
        Ok(())
    }

    /// Marks the resident points `ids` as used now (in id order).
    fn touch(&mut self, ids: &[u32]) {
        for id in ids {
            if let Some(e) = self.entries.get_mut(id) {
                self.clock += 1;
                e.1 = self.clock;
            }
        }
    }
}

impl Image {
    /// Writes `.png` (sRGB, clamped) or `.exr` (linear RGB f32), atomically; other extensions
    /// are an error.
    pub fn save(&self, path: &std::path::Path) -> Result<(), OocError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let (w, h) = (self.width, self.height);
        let written = match ext.as_deref() {
            Some("png") => {
                let rgba = self.to_rgba8();
                crate::atomic_file::write_atomic(path, |out| {
                    image::ImageEncoder::write_image(
                        image::codecs::png::PngEncoder::new(out),
                        &rgba,
                        w,
                        h,
                        image::ExtendedColorType::Rgba8,
                    )
                    .map_err(std::io::Error::other)
                })
            }
            Some("exr") => crate::atomic_file::write_atomic(path, |out| {
                image::ImageEncoder::write_image(
                    image::codecs::openexr::OpenExrEncoder::new(out),
                    bytemuck::cast_slice(&self.pixels),
                    w,
                    h,
                    image::ExtendedColorType::Rgb32F,
                )
                .map_err(std::io::Error::other)
            }),
            _ => {
                return Err(OocError::Invalid(format!(
                    "{}: the image must end in .png or .exr",
                    path.display()
                )))
            }
        };
        written.map_err(|e| OocError::io(path, e))
    }
}
