//! The per-receiver loop of §3.1.1, laid out for throughput: every blocker
//! triangle of a receiver goes through the same arithmetic as
//! [`Rasterizer::draw`](crate::Rasterizer::draw), bit for bit, but in two
//! phases so that the first runs 16 triangles wide in SIMD registers.
//!
//! 1. **Setup** (the paper's Table 2 "transform": moving blockers into the
//!    receiver's frame and culling them), 16 triangles at a time with no
//!    per-triangle branch: the three corners go into the tangent frame, the
//!    triangle is culled below the horizon, through the receiver, as a back
//!    face, as one the receiver skips, or as a near chord of the receiver's
//!    own body (its object, or the touching parts it belongs to), which is
//!    replaced by the fine triangles it stands for ([`replaced`]); the three
//!    edge-plane normals are computed and turned into plane-table cells
//!    (skipped when the whole chunk is culled), and the survivors' cells are
//!    appended to a list.
//! 2. **Lookup** (the paper's "rasterization"): per survivor, the three plane
//!    masks are ANDed and ORed into the visibility mask, one whole mask row
//!    per SIMD lane.
//!
//! # Clusters
//! The 16 triangles of a setup chunk are consecutive in their object's index
//! buffer, which for scanned and authored meshes (and meshoptimizer's
//! simplified ones) keeps them close in space. Each chunk's world bounding
//! box is computed per frame, so it holds for rigid, skinned and deformed
//! poses alike; a receiver skips every chunk whose box lies below its
//! tangent plane (§3.2, hierarchical culling). The test keeps a margin of
//! 10⁻⁵ of the magnitude of the coordinates involved, far above the
//! rounding of the per-triangle test, so that a skipped chunk holds only
//! triangles the per-triangle test would cull too: the masks are identical
//! with and without it.
//!
//! # Instruction sets
//! The loop is written once, as plain fixed-width loops that the compiler
//! vectorizes, and compiled three times: for AVX-512, for AVX2 + FMA, and for
//! the baseline of the build target. [`Simd::Auto`] picks the widest one
//! the running CPU has (never what the build machine had), so a plain
//! `cargo build --release` is fast everywhere. Rust never fuses a multiply
//! and an add on its own, so the three give identical masks; the tests hold
//! them to that.

use std::ops::Range;
use std::time::{Duration, Instant};

use glam::{Mat3, Vec3};
use shadow_core::{Error, Result};

use crate::csr::Csr;
use crate::lut::{PlaneLut, plane_code, row_code};
use crate::mask::{Mask, MaskRow};
use crate::rasterize::{Blockers, TangentFrame, edge_planes, replaced};

/// Triangles per setup chunk, and per cluster.
pub(crate) const LANES: usize = 16;

/// Which compilation of the per-receiver loop runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Simd {
    /// The widest path the running CPU supports (detected at run time).
    #[default]
    Auto,
    /// The build target's baseline instructions (SSE2 on x86-64): what any
    /// CPU runs.
    Portable,
    /// AVX2 and FMA (x86-64 only).
    Avx2,
    /// AVX-512 F/BW/DQ/VL (x86-64 only).
    Avx512,
}

impl Simd {
    /// The path this CPU can run: `Auto` becomes the widest available; an
    /// explicit path the CPU lacks is an error naming it.
    pub fn resolve(self) -> Result<Simd> {
        let available = Simd::available();
        match self {
            Simd::Auto => Ok(*available.last().unwrap_or(&Simd::Portable)),
            s if available.contains(&s) => Ok(s),
            s => Err(Error::config(
                "hemi-raster",
                format!("the {s:?} path was asked for, but this CPU only runs {available:?}"),
            )),
        }
    }

    /// The paths this CPU runs, narrowest first.
    pub fn available() -> Vec<Simd> {
        let mut paths = vec![Simd::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                paths.push(Simd::Avx2);
                if ["avx512f", "avx512bw", "avx512dq", "avx512vl"]
                    .iter()
                    .all(|f| avx512_feature(f))
                {
                    paths.push(Simd::Avx512);
                }
            }
        }
        paths
    }
}

#[cfg(target_arch = "x86_64")]
fn avx512_feature(name: &str) -> bool {
    match name {
        "avx512f" => std::arch::is_x86_feature_detected!("avx512f"),
        "avx512bw" => std::arch::is_x86_feature_detected!("avx512bw"),
        "avx512dq" => std::arch::is_x86_feature_detected!("avx512dq"),
        _ => std::arch::is_x86_feature_detected!("avx512vl"),
    }
}

/// A frame's blocker triangles laid out for the loop: every triangle of
/// the frame (the fine level, object by object), then, with the mesh
/// hierarchy, its coarse triangles (group by group), each group padded to
/// whole chunks with NaN triangles, which every test culls. One layout, so
/// that a triangle of either level is known by its slot alone. Built once
/// per frame.
#[derive(Clone, Debug, Default)]
pub(crate) struct Corners {
    /// By corner, struct of arrays (ax, ay, az, bx, …, cz in world space),
    /// for reading whole chunks; empty when only listed triangles are read.
    corners: [Vec<f32>; 9],
    /// The same corners by triangle (slot), for reading listed triangles:
    /// one bounds check and one or two cache lines per triangle, where the
    /// columns take nine of each.
    by_slot: Vec<[f32; 9]>,
    /// Per chunk, with the columns: the world bounding box of its corners
    /// (centre, half size).
    boxes: Vec<(Vec3, Vec3)>,
    /// Real (unpadded) fine triangles.
    fine_triangles: usize,
    /// Real coarse triangles.
    coarse_triangles: usize,
    /// Per group, fine (one per object) then coarse: its chunks and whether
    /// its back faces are culled.
    groups: Vec<Group>,
    /// How many of `groups` are fine.
    fine_groups: usize,
}

#[derive(Clone, Debug)]
struct Group {
    chunks: Range<usize>,
    cull: bool,
}

/// What the loop reads of a [`Corners`]: whole chunks (the columns and
/// their boxes, and the slots too), or listed triangles only (the slots).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Reading {
    Chunks,
    Slots,
}

/// A frame's coarse level: triangles (vertex indices into the frame's
/// [`Blockers`]) and their groups, (triangle range, back-face culling).
pub(crate) struct CoarseLevel<'a> {
    pub(crate) triangles: &'a [[u32; 3]],
    pub(crate) groups: Vec<(Range<usize>, bool)>,
}

impl Corners {
    /// Lays out `blockers`' triangles, object by object, and then those of
    /// `coarse`, group by group.
    pub(crate) fn new(
        blockers: &Blockers,
        coarse: Option<&CoarseLevel>,
        reading: Reading,
    ) -> Corners {
        let mut out = Corners::default();
        for (range, cull) in &blockers.objects {
            out.push(blockers, &blockers.triangles[range.clone()], *cull, reading);
        }
        out.fine_groups = out.groups.len();
        out.fine_triangles = blockers.triangles.len();
        if let Some(coarse) = coarse {
            for (range, cull) in &coarse.groups {
                out.push(blockers, &coarse.triangles[range.clone()], *cull, reading);
            }
            out.coarse_triangles = coarse.triangles.len();
        }
        out
    }

    /// Appends one group's `triangles`, padded to whole chunks, and (when
    /// chunks are read) their columns and boxes.
    fn push(&mut self, blockers: &Blockers, triangles: &[[u32; 3]], cull: bool, reading: Reading) {
        let start = self.by_slot.len();
        let padded = (start + triangles.len()).next_multiple_of(LANES);
        self.by_slot.resize(padded, [f32::NAN; 9]);
        for (slot, t) in (start..).zip(triangles) {
            for (k, &i) in t.iter().enumerate() {
                let p = blockers.position(i as usize);
                self.by_slot[slot][3 * k..3 * k + 3].copy_from_slice(&p.to_array());
            }
        }
        if reading == Reading::Chunks {
            for column in &mut self.corners {
                column.resize(padded, f32::NAN);
            }
            for slot in start..padded {
                for (k, column) in self.corners.iter_mut().enumerate() {
                    column[slot] = self.by_slot[slot][k];
                }
            }
            for chunk in start / LANES..padded / LANES {
                let lanes = chunk * LANES..(chunk + 1) * LANES;
                // `f32::min`/`max` skip the NaN padding.
                let extent = |axis: usize| {
                    (0..3).fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), k| {
                        let column = &self.corners[3 * k + axis][lanes.clone()];
                        (
                            column.iter().copied().fold(lo, f32::min),
                            column.iter().copied().fold(hi, f32::max),
                        )
                    })
                };
                let [(x0, x1), (y0, y1), (z0, z1)] = [0, 1, 2].map(extent);
                let (lo, hi) = (Vec3::new(x0, y0, z0), Vec3::new(x1, y1, z1));
                self.boxes.push(((lo + hi) * 0.5, (hi - lo) * 0.5));
            }
        }
        self.groups.push(Group {
            chunks: start / LANES..padded / LANES,
            cull,
        });
    }

    /// Where triangle `t` of object `o` goes when a scene whose objects
    /// have `triangle_counts` is laid out by [`Corners::new`], one object
    /// after another.
    pub(crate) fn slot_bases(triangle_counts: impl IntoIterator<Item = usize>) -> Vec<u32> {
        let mut base = 0;
        triangle_counts
            .into_iter()
            .map(|n| {
                let b = base as u32;
                base += n.next_multiple_of(LANES);
                b
            })
            .collect()
    }

    /// Whether `chunk`'s box lies below the receiver's tangent plane.
    #[inline(always)]
    fn below(&self, chunk: usize, frame: &Frame) -> bool {
        let (centre, half) = self.boxes[chunk];
        frame.below(centre, half)
    }

    /// The nine corner columns of `chunk` (laid out for
    /// [`Reading::Chunks`]).
    #[inline(always)]
    fn chunk(&self, chunk: usize) -> [&[f32; LANES]; 9] {
        let lanes = chunk * LANES..(chunk + 1) * LANES;
        std::array::from_fn(|k| {
            self.corners[k][lanes.clone()]
                .try_into()
                .expect("columns are whole chunks")
        })
    }

    /// Reads the triangles at `entries`' slots (at most [`LANES`]) into
    /// `columns` and their culling into `flags`; lanes past the end get NaN
    /// corners, which every test culls.
    #[inline(always)]
    fn gather(&self, entries: &[Entry], columns: &mut [[f32; LANES]; 9], flags: &mut LaneFlags) {
        for (l, entry) in entries.iter().enumerate() {
            let corners = &self.by_slot[entry.slot()];
            for k in 0..9 {
                columns[k][l] = corners[k];
            }
            flags.cull[l] = entry.cull();
            flags.chords[l] = entry.chords();
        }
        for l in entries.len()..LANES {
            for column in columns.iter_mut() {
                column[l] = f32::NAN;
            }
        }
    }

    /// The world-space corners of the triangle at `slot`.
    pub(crate) fn triangle(&self, slot: usize) -> [Vec3; 3] {
        let c = &self.by_slot[slot];
        [0, 3, 6].map(|k| Vec3::new(c[k], c[k + 1], c[k + 2]))
    }

    /// The fine groups (one per object), then the coarse ones.
    fn fine(&self) -> &[Group] {
        &self.groups[..self.fine_groups]
    }

    fn coarse(&self) -> &[Group] {
        &self.groups[self.fine_groups..]
    }

    /// The slot of the coarse level's first triangle: coarse triangles are
    /// known to the hierarchy by their slot from there.
    fn coarse_base(&self) -> usize {
        Corners::slots(self.fine())
    }

    /// The slots of `groups`, padding included.
    fn slots(groups: &[Group]) -> usize {
        groups.iter().map(|g| g.chunks.len() * LANES).sum()
    }

    /// The entries of `group`'s triangles (padding included, which every
    /// test culls), with near chords culled when `chords`.
    fn group_entries(group: &Group, chords: bool) -> impl Iterator<Item = Entry> + '_ {
        let slots = group.chunks.start * LANES..group.chunks.end * LANES;
        slots.map(move |slot| Entry::new(slot as u32, group.cull, chords))
    }
}

/// A triangle of a per-receiver list: its slot in a frame's [`Corners`],
/// and how it is culled (back faces; near chords of the receiver's own
/// body, which [`replaced`] swaps for fine triangles), packed in one word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct Entry(u32);

impl Entry {
    const CULL: u32 = 1 << 31;
    const CHORDS: u32 = 1 << 30;

    /// `slot` must be below 2³⁰: a billion triangles, far beyond any frame.
    pub(crate) fn new(slot: u32, cull: bool, chords: bool) -> Entry {
        debug_assert!(slot < Entry::CHORDS, "slot {slot} out of range");
        Entry(slot | u32::from(cull) << 31 | u32::from(chords) << 30)
    }

    #[inline(always)]
    pub(crate) fn slot(self) -> usize {
        (self.0 & !(Entry::CULL | Entry::CHORDS)) as usize
    }

    #[inline(always)]
    pub(crate) fn cull(self) -> bool {
        self.0 & Entry::CULL != 0
    }

    #[inline(always)]
    pub(crate) fn chords(self) -> bool {
        self.0 & Entry::CHORDS != 0
    }
}

/// Per lane of a setup chunk: whether back faces are culled, whether near
/// chords are dropped (and replaced), and (one bit per lane) whether the
/// receiver skips the triangle outright.
struct LaneFlags {
    cull: [bool; LANES],
    chords: [bool; LANES],
    skip: u32,
}

impl LaneFlags {
    #[inline(always)]
    fn splat(cull: bool, chords: bool) -> LaneFlags {
        LaneFlags {
            cull: [cull; LANES],
            chords: [chords; LANES],
            skip: 0,
        }
    }
}

/// What one receiver rasterizes, from one frame's [`Corners`].
pub(crate) enum Candidates<'a> {
    /// Every fine triangle of the frame.
    All(&'a Corners),
    /// §3.2's two levels: the coarse triangles of every body (coarse group)
    /// but those the receiver skips (`excluded`, by slot from the coarse
    /// level's first) and the near chords of its own (coarse group `own`),
    /// which [`replaced`] swaps for their `regions`; and the near fine
    /// triangles, listed by slot.
    TwoLevel {
        corners: &'a Corners,
        own: usize,
        near: &'a [Entry],
        excluded: &'a [u32],
        regions: &'a Csr<Entry>,
    },
    /// A potentially visible set (§3.2, [`crate::pvs`]): listed triangles
    /// of either level; with two levels, what replaces the listed near
    /// chords: rows `kept.1` of `kept.0`, one for each of the first entries
    /// (the others replace nothing).
    Listed {
        corners: &'a Corners,
        entries: &'a [Entry],
        kept: Option<(&'a Csr<Entry>, Range<usize>)>,
    },
}

impl Candidates<'_> {
    /// How many triangles the receiver considers before any frame is seen
    /// (the paper's Table 1 "Avg. #Tris" per vertex, but for the fine
    /// triangles that replace near chords, which the loop counts per frame).
    pub(crate) fn count(&self) -> usize {
        match self {
            Candidates::All(corners) => corners.fine_triangles,
            Candidates::TwoLevel {
                corners,
                near,
                excluded,
                ..
            } => corners.coarse_triangles - excluded.len() + near.len(),
            Candidates::Listed { entries, .. } => entries.len(),
        }
    }

    /// Every candidate that does not depend on the frame: what the
    /// per-receiver loop considers, for building visible sets (not for the
    /// loop itself). With two levels, add the [`Candidates::replacements`]
    /// of the coarse triangles [`replaced`] in the frame.
    pub(crate) fn entries(&self) -> Vec<Entry> {
        match *self {
            Candidates::All(corners) => (corners.fine().iter())
                .flat_map(|g| Corners::group_entries(g, false))
                .collect(),
            Candidates::TwoLevel {
                corners,
                own,
                near,
                excluded,
                ..
            } => {
                let base = corners.coarse_base();
                (corners.coarse().iter().enumerate())
                    .flat_map(|(o, g)| Corners::group_entries(g, o == own))
                    .filter(|e| excluded.binary_search(&((e.slot() - base) as u32)).is_err())
                    .chain(near.iter().copied())
                    .collect()
            }
            Candidates::Listed { entries, .. } => entries.to_vec(),
        }
    }

    /// The fine triangles that replace candidate `entry` when the frame
    /// finds it [`replaced`]: its region for a coarse triangle of the
    /// receiver's own body, nothing otherwise.
    pub(crate) fn replacements(&self, entry: Entry) -> &[Entry] {
        match *self {
            Candidates::TwoLevel {
                corners, regions, ..
            } if entry.chords() => regions.of(entry.slot() - corners.coarse_base()),
            _ => &[],
        }
    }

    /// What replaces the near chord listed at `position`, when the frame
    /// replaces it (only visible sets list near chords).
    #[inline(always)]
    fn kept(&self, position: usize) -> &[Entry] {
        match self {
            Candidates::Listed {
                kept: Some((rows, range)),
                ..
            } if position < range.len() => rows.of(range.start + position),
            _ => &[],
        }
    }

    /// The frame's layout the candidates are read from.
    #[inline(always)]
    fn corners(&self) -> &Corners {
        match *self {
            Candidates::All(corners)
            | Candidates::TwoLevel { corners, .. }
            | Candidates::Listed { corners, .. } => corners,
        }
    }
}

/// Per-thread buffers of the loop, reused from receiver to receiver: after
/// the first few receivers it allocates nothing.
#[derive(Default)]
pub(crate) struct Scratch {
    /// Three plane-cell codes per surviving triangle.
    survivors: Vec<u32>,
    /// The listed triangles: near ones or a visible set, and the fine
    /// triangles that replace near chords.
    queue: Vec<Entry>,
    /// Time and counts of the two phases, when profiling.
    profile: Option<LoopProfile>,
}

impl Scratch {
    /// Buffers that also time the loop's phases.
    pub(crate) fn profiling() -> Scratch {
        Scratch {
            profile: Some(LoopProfile::default()),
            ..Scratch::default()
        }
    }

    /// What the phases took so far, when profiling.
    pub(crate) fn profile(&self) -> Option<LoopProfile> {
        self.profile
    }
}

/// Where the loop's time went, summed over receivers (the paper's Table 2
/// split): the setup ("transform": blockers into the receiver's frame,
/// culling, plane cells) and the lookups ("rasterization").
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct LoopProfile {
    pub(crate) transform: Duration,
    pub(crate) rasterization: Duration,
    /// Triangles that survived culling and were looked up.
    pub(crate) survivors: u64,
    /// Fine triangles listed in place of replaced coarse ones.
    pub(crate) replacements: u64,
}

/// The visibility mask of the receiver with tangent frame `frame`, on the
/// `simd` path (which must come from [`Simd::resolve`]).
pub(crate) fn receiver_mask<W: MaskRow>(
    simd: Simd,
    lut: &PlaneLut<W>,
    frame: &TangentFrame,
    candidates: &Candidates,
    scratch: &mut Scratch,
) -> Mask<W> {
    let job = Job {
        lut,
        frame,
        candidates,
    };
    match simd {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::resolve` only yields Avx512 on CPUs that have it.
        Simd::Avx512 => unsafe { job.run_avx512(scratch) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::resolve` only yields Avx2 on CPUs that have it.
        Simd::Avx2 => unsafe { job.run_avx2(scratch) },
        _ => job.run(scratch),
    }
}

struct Job<'a, W: MaskRow> {
    lut: &'a PlaneLut<W>,
    frame: &'a TangentFrame,
    candidates: &'a Candidates<'a>,
}

/// The receiver's origin and the rows of world-to-tangent, with what the
/// box test needs of them computed once per receiver.
#[derive(Clone, Copy)]
struct Frame {
    o: Vec3,
    t: Vec3,
    b: Vec3,
    n: Vec3,
    /// |n| componentwise, and Σ|o|: the box test's reach and rounding scale.
    n_abs: Vec3,
    o_scale: f32,
}

impl Frame {
    fn new(o: Vec3, to_world: Mat3) -> Frame {
        let n = to_world.z_axis;
        Frame {
            o,
            t: to_world.x_axis,
            b: to_world.y_axis,
            n,
            n_abs: n.abs(),
            o_scale: o.abs().element_sum(),
        }
    }

    /// World point (x, y, z) in tangent coordinates: the arithmetic of
    /// [`TangentFrame::to_local`], term for term.
    #[inline(always)]
    fn local(&self, x: f32, y: f32, z: f32) -> Vec3 {
        let (t, b, n, o) = (self.t, self.b, self.n, self.o);
        let (dx, dy, dz) = (x - o.x, y - o.y, z - o.z);
        Vec3::new(
            t.x * dx + t.y * dy + t.z * dz,
            b.x * dx + b.y * dy + b.z * dz,
            n.x * dx + n.y * dy + n.z * dz,
        )
    }

    /// Whether the box (centre, half size) lies below the tangent plane with
    /// a margin far above the rounding of [`Frame::local`] (module docs).
    #[inline(always)]
    fn below(&self, centre: Vec3, half: Vec3) -> bool {
        let top = self.n.dot(centre - self.o) + self.n_abs.dot(half);
        let scale = self.o_scale + centre.abs().element_sum() + half.element_sum();
        top < -1e-5 * scale
    }
}

impl<W: MaskRow> Job<'_, W> {
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2,fma,bmi1,bmi2,popcnt")]
    fn run_avx512(&self, scratch: &mut Scratch) -> Mask<W> {
        self.run(scratch)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,popcnt")]
    fn run_avx2(&self, scratch: &mut Scratch) -> Mask<W> {
        self.run(scratch)
    }

    #[inline(always)]
    fn run(&self, scratch: &mut Scratch) -> Mask<W> {
        let m = self.frame.to_world();
        let frame = Frame::new(self.frame.origin(), m);
        let resolution = self.lut.resolution() as u32;
        let start = scratch.profile.is_some().then(Instant::now);
        let Scratch {
            survivors,
            queue,
            profile,
        } = scratch;
        let slots = match *self.candidates {
            Candidates::All(corners) => Corners::slots(corners.fine()),
            Candidates::TwoLevel { corners, .. } => Corners::slots(corners.coarse()),
            Candidates::Listed { .. } => 0,
        };
        // Listed triangles make room for themselves as they come.
        fit(survivors, slots);
        // Plain loops and direct calls only: a closure or an iterator
        // adaptor here would be compiled apart from the `target_feature`
        // function, for the baseline instruction set.
        let mut count = 0;
        queue.clear();
        let listed = match *self.candidates {
            Candidates::All(corners) => {
                for g in corners.fine() {
                    for chunk in g.chunks.clone() {
                        if !corners.below(chunk, &frame) {
                            let c = corners.chunk(chunk);
                            let flags = LaneFlags::splat(g.cull, false);
                            setup::<W>(c, &flags, &frame, resolution, survivors, &mut count);
                        }
                    }
                }
                0
            }
            Candidates::TwoLevel {
                corners,
                own,
                near,
                excluded,
                regions,
            } => {
                let first = corners.coarse_base() / LANES;
                let mut next = 0;
                for (o, g) in corners.coarse().iter().enumerate() {
                    for chunk in g.chunks.clone() {
                        // The chunk's excluded lanes (the list is sorted).
                        let base = (chunk - first) * LANES;
                        let mut skip = 0u32;
                        while next < excluded.len() && (excluded[next] as usize) < base + LANES {
                            skip |= 1 << (excluded[next] as usize - base);
                            next += 1;
                        }
                        if !corners.below(chunk, &frame) {
                            let c = corners.chunk(chunk);
                            let mut flags = LaneFlags::splat(g.cull, o == own);
                            flags.skip = skip;
                            let mut bits =
                                setup::<W>(c, &flags, &frame, resolution, survivors, &mut count);
                            while bits != 0 {
                                let slot = base + bits.trailing_zeros() as usize;
                                queue.extend_from_slice(regions.of(slot));
                                bits &= bits - 1;
                            }
                        }
                    }
                }
                // Near triangles and replacements are read by slot; their
                // boxes would not cull them.
                queue.extend_from_slice(near);
                near.len()
            }
            Candidates::Listed { entries, .. } => {
                queue.extend_from_slice(entries);
                entries.len()
            }
        };
        self.listed(queue, &frame, resolution, survivors, &mut count);
        if let Some(p) = profile.as_mut() {
            p.replacements += (queue.len() - listed) as u64;
        }
        let setup_end = start.map(|_| Instant::now());
        let mut mask = Mask::EMPTY;
        self.lookup(&survivors[..count], &mut mask);
        if let (Some(p), Some(start), Some(setup_end)) = (profile, start, setup_end) {
            p.transform += setup_end - start;
            p.rasterization += setup_end.elapsed();
            p.survivors += (count / 3) as u64;
        }
        mask
    }

    /// Phase 1 on the listed triangles in `queue`, 16 at a time, read by
    /// slot. A near chord the frame replaces (only visible sets list near
    /// chords; the hierarchy queues its replacements before) queues what
    /// replaces it, so that only the queue's last chunk is partly empty.
    #[inline(always)]
    fn listed(
        &self,
        queue: &mut Vec<Entry>,
        frame: &Frame,
        resolution: u32,
        survivors: &mut Vec<u32>,
        count: &mut usize,
    ) {
        let corners = self.candidates.corners();
        let mut columns = [[0.0f32; LANES]; 9];
        let mut flags = LaneFlags::splat(false, false);
        let mut next = 0;
        while next < queue.len() {
            let end = queue.len().min(next + LANES);
            corners.gather(&queue[next..end], &mut columns, &mut flags);
            fit(survivors, *count / 3 + LANES);
            let c = [0, 1, 2, 3, 4, 5, 6, 7, 8].map(|k| &columns[k]);
            let mut bits = setup::<W>(c, &flags, frame, resolution, survivors, count);
            while bits != 0 {
                let position = next + bits.trailing_zeros() as usize;
                queue.extend_from_slice(self.candidates.kept(position));
                bits &= bits - 1;
            }
            next = end;
        }
    }

    /// Phase 2: per surviving triangle, AND its three plane masks and OR
    /// the result into `mask`. A plane mask is a stored mask, mirrored top to
    /// bottom (with folded rows, by reading the two halves of storage
    /// swapped) and complemented within the disk as its [`row_code`] says
    /// (see [`PlaneLut`]). The complement is taken against all ones here,
    /// which also sets the pixels outside the disk, so the mask is clipped to
    /// the disk once at the end rather than per triangle.
    #[inline(always)]
    fn lookup(&self, survivors: &[u32], mask: &mut Mask<W>) {
        let half = W::RESOLUTION / 2;
        let rows = self.lut.rows();
        let mut acc = W::EMPTY_ROWS;
        let (top, bottom) = acc.as_mut().split_at_mut(half);
        for (n, s) in survivors.chunks_exact(3).enumerate() {
            if let Some(ahead) = survivors.get(3 * (n + AHEAD)..3 * (n + AHEAD) + 3) {
                for &code in ahead {
                    let start = (code >> 1) as usize & !(W::RESOLUTION - 1);
                    prefetch(&rows[start..start + W::RESOLUTION]);
                }
            }
            let plane = |k: usize| {
                let code = s[k];
                let top = (code >> 1) as usize;
                let bottom = top ^ half;
                let flip = if code & 1 != 0 { !W::ZERO } else { W::ZERO };
                (&rows[top..top + half], &rows[bottom..bottom + half], flip)
            };
            let ((a0, a1, fa), (b0, b1, fb), (c0, c1, fc)) = (plane(0), plane(1), plane(2));
            for i in 0..half {
                top[i] = top[i] | ((a0[i] ^ fa) & (b0[i] ^ fb) & (c0[i] ^ fc));
                bottom[i] = bottom[i] | ((a1[i] ^ fa) & (b1[i] ^ fb) & (c1[i] ^ fc));
            }
        }
        let disk = self.lut.disk().rows();
        for (out, (&a, &d)) in mask
            .rows_mut()
            .iter_mut()
            .zip(acc.as_ref().iter().zip(disk))
        {
            *out = a & d;
        }
    }
}

/// How many survivors ahead the lookup prefetches plane masks: the table
/// (3 MB at 128²) lives in L3, and a survivor's three masks are six cache
/// lines at random places; fetching them early overlaps their latency with
/// the ANDs and ORs of the survivors before. Eight survivors (48 lines) ahead
/// was best on the 2-core AMD EPYC (AVX-512): its look-ups took 10–15%
/// longer 16 ahead (more lines asked for than the core tracks at once) and
/// 4 or 12 ahead, on the human with and without potentially visible sets.
const AHEAD: usize = 8;

/// Asks for `value`'s cache lines; never faults.
#[inline(always)]
fn prefetch<T>(value: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = value.as_ptr().cast::<i8>();
        for offset in (0..size_of_val(value)).step_by(64) {
            // SAFETY: a prefetch is a hint; it reads nothing and never faults.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

/// Makes room for three codes per slot.
fn fit(survivors: &mut Vec<u32>, slots: usize) {
    let need = 3 * slots;
    if survivors.len() < need {
        survivors.resize(need, 0);
    }
}

/// Phase 1 on one chunk, given by its nine corner columns: appends the plane
/// codes of its surviving triangles at `survivors[*count..]`, culling back
/// faces and the skipped lanes, and dropping near chords, in the lanes
/// `flags` says. Returns the lanes [`replaced`] (one bit each).
/// Straight-line code over fixed-size arrays: the compiler turns the first
/// loop into SIMD instructions, 16 triangles per pass.
#[inline(always)]
fn setup<W: MaskRow>(
    c: [&[f32; LANES]; 9],
    flags: &LaneFlags,
    frame: &Frame,
    resolution: u32,
    survivors: &mut [u32],
    count: &mut usize,
) -> u32 {
    // Each step is a short loop over the lanes with arrays in and out: the
    // shape the vectorizer turns into a few SIMD instructions per step.
    let mut local = [[0.0f32; LANES]; 9];
    for k in 0..3 {
        for l in 0..LANES {
            let p = frame.local(c[3 * k][l], c[3 * k + 1][l], c[3 * k + 2][l]);
            local[3 * k][l] = p.x;
            local[3 * k + 1][l] = p.y;
            local[3 * k + 2][l] = p.z;
        }
    }
    let mut planes = [[0.0f32; LANES]; 9];
    let mut keep = [false; LANES];
    let mut above = [false; LANES];
    let mut behind = [false; LANES];
    for l in 0..LANES {
        let e = edge_planes(lane(&local, l), flags.cull[l]);
        for (k, m) in e.normals.iter().enumerate() {
            planes[3 * k][l] = m.x;
            planes[3 * k + 1][l] = m.y;
            planes[3 * k + 2][l] = m.z;
        }
        keep[l] = e.kept & (flags.skip >> l & 1 == 0);
        above[l] = e.above;
        behind[l] = e.behind;
    }
    // The chord test only where a lane asks for it (the receiver's own
    // coarse body): most chunks skip it.
    let mut chords = false;
    for &c in &flags.chords {
        chords |= c;
    }
    let mut gone = 0u32;
    if chords {
        for l in 0..LANES {
            let swap = flags.chords[l]
                & (flags.skip >> l & 1 == 0)
                & replaced(lane(&local, l), above[l], behind[l]);
            gone |= u32::from(swap) << l;
            keep[l] &= !swap;
        }
    }
    // Coherent chunks are often culled whole (a back-facing patch, a patch
    // edge-on): then the plane codes are not needed.
    let mut survived = 0u32;
    for (l, &k) in keep.iter().enumerate() {
        survived |= u32::from(k) << l;
    }
    if survived == 0 {
        return gone;
    }
    let mut codes = [[0u32; LANES]; 3];
    for (e, codes) in codes.iter_mut().enumerate() {
        for (l, code) in codes.iter_mut().enumerate() {
            let m = Vec3::new(planes[3 * e][l], planes[3 * e + 1][l], planes[3 * e + 2][l]);
            *code = row_code::<W>(plane_code(m, resolution));
        }
    }
    // Compaction, survivor by survivor.
    let mut bits = survived;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        survivors[*count..*count + 3].copy_from_slice(&[codes[0][l], codes[1][l], codes[2][l]]);
        *count += 3;
    }
    gone
}

/// Lane `l`'s triangle from nine corner columns.
#[inline(always)]
fn lane(columns: &[[f32; LANES]; 9], l: usize) -> [Vec3; 3] {
    let corner = |k: usize| Vec3::new(columns[k][l], columns[k + 1][l], columns[k + 2][l]);
    [corner(0), corner(3), corner(6)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rasterize::Rasterizer;
    use crate::test_util::{grid, icosphere};
    use shadow_core::{Brdf, Camera, Mesh, Object, Scene};
    use std::sync::Arc;

    const FAR: Vec3 = Vec3::new(40.0, -3.0, 25.0);

    /// A bumpy closed sphere over an open floor, with a second small sphere
    /// sunk into the floor (interpenetration), far from the origin so that
    /// rounding in the frame transform is exercised.
    fn scene() -> Scene {
        let bumpy = icosphere(Vec3::new(0.0, 0.7, 0.0), 0.5, 3);
        let positions = bumpy
            .positions()
            .iter()
            .map(|p| {
                let d = *p - Vec3::new(0.0, 0.7, 0.0);
                Vec3::new(0.0, 0.7, 0.0) + d * (1.0 + 0.25 * (9.0 * d.x).sin() * (7.0 * d.z).cos())
            })
            .collect();
        let bumpy = Mesh::new("bumpy", positions, None, bumpy.triangles().to_vec()).unwrap();
        let material = Brdf::lambert(Vec3::splat(0.5)).unwrap();
        let objects = [
            bumpy,
            grid(0.0, 1.5, 12),
            icosphere(Vec3::new(0.8, 0.05, 0.3), 0.2, 1),
        ]
        .into_iter()
        .map(|m| {
            let far = m.positions().iter().map(|&p| p + FAR).collect();
            Object {
                mesh: Arc::new(Mesh::new(m.name(), far, None, m.triangles().to_vec()).unwrap()),
                material,
            }
        })
        .collect();
        let camera = Camera::new(FAR + Vec3::new(0.0, 3.0, 5.0), FAR, Vec3::Y, 0.8, 8, 8).unwrap();
        Scene::still("kernel test", objects, camera).unwrap()
    }

    /// The scalar reference: every candidate triangle through
    /// [`Rasterizer::draw`].
    fn reference<W: MaskRow>(
        raster: &Rasterizer<W>,
        frame: &TangentFrame,
        triangles: impl IntoIterator<Item = ([Vec3; 3], bool)>,
    ) -> Mask<W> {
        let mut mask = Mask::EMPTY;
        for (t, cull) in triangles {
            raster.draw(t.map(|p| frame.to_local(p)), cull, &mut mask);
        }
        mask
    }

    fn every_path_matches_draw<W: MaskRow>(lut_resolution: usize) {
        let scene = scene();
        let geometry = scene.frame_geometry(0).unwrap();
        let cull = [true, false, true];
        let blockers = Blockers::new(&geometry, &cull);
        let raster = Rasterizer::<W>::new(lut_resolution).unwrap();
        let bases = Corners::slot_bases(blockers.objects.iter().map(|(r, _)| r.len()));
        let object_of = |t: usize| {
            blockers
                .objects
                .iter()
                .position(|(r, _)| r.contains(&t))
                .unwrap()
        };
        let entry = |t: usize, chords: bool| {
            let o = object_of(t);
            let slot = bases[o] as usize + t - blockers.objects[o].0.start;
            Entry::new(slot as u32, cull[o], chords)
        };
        // A coarse level: every third triangle of each object, standing for
        // itself and the two after it (its region), by coarse slot.
        let mut coarse_triangles = Vec::new();
        let mut groups = Vec::new();
        let mut regions = Vec::new();
        for (range, cull) in &blockers.objects {
            let start = coarse_triangles.len();
            for t in range.clone().step_by(3) {
                coarse_triangles.push(blockers.triangles[t]);
                regions.push((t..(t + 3).min(range.end)).collect::<Vec<_>>());
            }
            groups.push((start..coarse_triangles.len(), *cull));
            regions.resize(regions.len().next_multiple_of(LANES), Vec::new());
        }
        let region_entries = Csr::from_lists(
            (regions.iter()).map(|r| r.iter().map(|&t| entry(t, false)).collect::<Vec<_>>()),
        );
        let coarse = CoarseLevel {
            triangles: &coarse_triangles,
            groups: groups.clone(),
        };
        let layout = Corners::new(&blockers, Some(&coarse), Reading::Chunks);
        let slots_only = Corners::new(&blockers, Some(&coarse), Reading::Slots);
        let world = |t: [u32; 3]| t.map(|i| blockers.position(i as usize));
        let object_of_vertex = |v: usize| {
            let mut first = 0;
            geometry
                .objects
                .iter()
                .position(|o| {
                    first += o.vertex_count();
                    v < first
                })
                .unwrap()
        };
        let mut scratch = Scratch::default();
        let (mut blocked, mut swapped) = (0, 0);
        for v in (0..blockers.vertex_count()).step_by(7) {
            let frame = blockers.frame(v);
            let truth = reference(
                &raster,
                &frame,
                blockers
                    .triangles
                    .iter()
                    .enumerate()
                    .map(|(t, &tri)| (world(tri), cull[object_of(t)])),
            );
            blocked += usize::from(!truth.is_empty());
            // Two levels: the coarse triangles but every seventh coarse slot
            // (excluded), the own object's near chords replaced by their
            // regions, and every fifth triangle as "near".
            let own = object_of_vertex(v);
            let near: Vec<usize> = (0..blockers.triangles.len()).step_by(5).collect();
            let excluded: Vec<u32> = (v as u32 % 7..regions.len() as u32).step_by(7).collect();
            let local = |t: [u32; 3]| world(t).map(|p| frame.to_local(p));
            let mut listed = near.clone();
            let mut coarse_kept = Vec::new();
            let mut slot = 0;
            for (o, (range, cull)) in groups.iter().enumerate() {
                for (k, &t) in coarse_triangles[range.clone()].iter().enumerate() {
                    if excluded.binary_search(&((slot + k) as u32)).is_ok() {
                        continue;
                    }
                    let planes = edge_planes(local(t), *cull);
                    if o == own && replaced(local(t), planes.above, planes.behind) {
                        listed.extend(&regions[slot + k]);
                        swapped += 1;
                    } else {
                        coarse_kept.push((world(t), *cull));
                    }
                }
                slot += range.len().next_multiple_of(LANES);
            }
            let two_truth = reference(
                &raster,
                &frame,
                coarse_kept.into_iter().chain(
                    listed
                        .iter()
                        .map(|&t| (world(blockers.triangles[t]), cull[object_of(t)])),
                ),
            );
            let near_slots: Vec<Entry> = near.iter().map(|&t| entry(t, false)).collect();
            let two_level = Candidates::TwoLevel {
                corners: &layout,
                own,
                near: &near_slots,
                excluded: &excluded,
                regions: &region_entries,
            };
            // The same candidates listed by slot, from either reading, each
            // near chord with its whole region kept: the listed near chords
            // are replaced as the frame finds them.
            let entries = two_level.entries();
            let kept = Csr::from_lists(entries.iter().map(|&e| two_level.replacements(e)));
            let rows = 0..entries.len();
            for simd in Simd::available() {
                let got = receiver_mask(
                    simd,
                    raster.lut(),
                    &frame,
                    &Candidates::All(&layout),
                    &mut scratch,
                );
                assert_eq!(got, truth, "{simd:?}, receiver {v}");
                let got = receiver_mask(simd, raster.lut(), &frame, &two_level, &mut scratch);
                assert_eq!(got, two_truth, "{simd:?} two-level, receiver {v}");
                for corners in [&layout, &slots_only] {
                    let candidates = Candidates::Listed {
                        corners,
                        entries: &entries,
                        kept: Some((&kept, rows.clone())),
                    };
                    let got = receiver_mask(simd, raster.lut(), &frame, &candidates, &mut scratch);
                    assert_eq!(got, two_truth, "{simd:?} listed, receiver {v}");
                }
            }
        }
        assert!(blocked > 20, "the scene must shadow: {blocked}");
        assert!(swapped > 20, "near chords must be replaced: {swapped}");
    }

    #[test]
    fn every_path_matches_the_scalar_rasterizer_bit_for_bit() {
        every_path_matches_draw::<u16>(32);
        every_path_matches_draw::<u32>(128);
        every_path_matches_draw::<u64>(64);
    }

    #[test]
    fn paths_resolve_to_what_the_cpu_has() {
        let available = Simd::available();
        assert_eq!(available[0], Simd::Portable);
        assert_eq!(Simd::Auto.resolve().unwrap(), *available.last().unwrap());
        assert_eq!(Simd::Portable.resolve().unwrap(), Simd::Portable);
        for s in [Simd::Avx2, Simd::Avx512] {
            assert_eq!(s.resolve().is_ok(), available.contains(&s));
        }
    }

    /// Chunks below the horizon are skipped whole: for a receiver on top of
    /// a floor-level sphere looking up, the floor's boxes are all below.
    #[test]
    fn boxes_below_the_tangent_plane_are_found() {
        let frame = Frame::new(
            Vec3::new(0.0, 1.0, 0.0),
            Mat3::from_cols(Vec3::X, Vec3::NEG_Z, Vec3::Y),
        );
        assert!(frame.below(Vec3::ZERO, Vec3::new(5.0, 0.5, 5.0)));
        assert!(!frame.below(Vec3::ZERO, Vec3::new(5.0, 1.0, 5.0)));
        assert!(!frame.below(Vec3::new(0.0, 2.0, 0.0), Vec3::splat(0.1)));
    }
}
