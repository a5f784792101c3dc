//! Stick-figure rendering of clips: animated GIFs and PNG contact sheets.
//!
//! Each picture has a side view (looking across the clip's main direction of travel, with the
//! terrain profile under the root) and a top view (direction of travel to the right, terrain
//! shaded by height, ground grid every 50 cm). Several clips are overlaid in distinct colours
//! and named in a legend; the camera follows the first clip's root. Rasterised with tiny-skia;
//! text uses a tiny embedded 3x5 bitmap font drawn as rectangles.

use crate::terrain::Heightmap;
use crate::{Context, Message, bail};
use std::path::Path;
use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, PixmapPaint, Rect, Stroke, Transform};
use zoo_motion::Clip;
use zoo_motion::glam::DVec3;

/// A clip to draw, with its legend label and the ground under it.
pub struct RenderClip {
    /// Legend text.
    pub label: String,
    /// The motion (cm, Y up).
    pub clip: Clip,
    /// The ground (`None`: flat floor at y = 0).
    pub terrain: Option<Heightmap>,
}

/// What to draw.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// First frame drawn.
    pub from: usize,
    /// One past the last frame drawn (clamped to the shortest clip).
    pub to: Option<usize>,
    /// Draw every k-th frame (GIF: `None` picks about 15 frames per second).
    pub every: Option<usize>,
    /// Print frame numbers.
    pub frame_numbers: bool,
}

const PALETTE: [(u8, u8, u8); 6] =
    [(30, 90, 200), (220, 60, 40), (30, 150, 60), (150, 60, 190), (230, 140, 0), (0, 150, 160)];
const GRID: (u8, u8, u8) = (200, 200, 205);
const GROUND: (u8, u8, u8) = (170, 150, 120);
const TEXT: (u8, u8, u8) = (40, 40, 40);

struct View {
    /// Horizontal direction of travel (unit, y = 0).
    dir: DVec3,
    /// To its left.
    left: DVec3,
}

/// The most grid lines of one direction in a view (one every 50 cm).
const MAX_GRID_LINES: usize = 1000;

fn ground(t: &Option<Heightmap>, x: f64, z: f64) -> f64 {
    t.as_ref().map_or(0.0, |t| t.height(x, z))
}

fn view_of(clip: &Clip, from: usize, to: usize) -> View {
    let d = clip.root_position(to - 1) - clip.root_position(from);
    let mut dir = DVec3::new(d.x, 0.0, d.z);
    if dir.length() < 30.0 {
        let r = clip.local_rotations[from * clip.joints()];
        dir = zoo_motion::facing::ground_forward(r, DVec3::Z);
    }
    let dir = dir.normalize_or(DVec3::Z);
    View { dir, left: DVec3::new(dir.z, 0.0, -dir.x) }
}

fn rgb(c: (u8, u8, u8)) -> Color {
    Color::from_rgba8(c.0, c.1, c.2, 255)
}

fn paint(c: Color) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(c);
    p.anti_alias = true;
    p
}

fn line(pm: &mut Pixmap, a: (f32, f32), b: (f32, f32), c: Color, w: f32) {
    let mut pb = PathBuilder::new();
    pb.move_to(a.0, a.1);
    pb.line_to(b.0, b.1);
    if let Some(path) = pb.finish() {
        let stroke = Stroke { width: w, ..Stroke::default() };
        pm.stroke_path(&path, &paint(c), &stroke, Transform::identity(), None);
    }
}

fn dot(pm: &mut Pixmap, p: (f32, f32), r: f32, c: Color) {
    if let Some(path) = PathBuilder::from_circle(p.0, p.1, r) {
        pm.fill_path(&path, &paint(c), FillRule::Winding, Transform::identity(), None);
    }
}

fn rect(pm: &mut Pixmap, x: f32, y: f32, w: f32, h: f32, c: Color) {
    if let Some(r) = Rect::from_xywh(x, y, w, h) {
        let mut p = paint(c);
        p.anti_alias = false;
        pm.fill_rect(r, &p, Transform::identity(), None);
    }
}

/// 3x5 bitmap glyphs, one row per entry, bit 2 = left column.
fn glyph(ch: char) -> [u8; 5] {
    match ch.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '-' => [0, 0, 7, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        '_' => [0, 0, 0, 0, 7],
        ':' => [0, 2, 0, 2, 0],
        '/' => [1, 1, 2, 4, 4],
        _ => [0; 5],
    }
}

/// Draws `text` with its top-left corner at (x, y); `px` is the size of one font pixel.
fn text(pm: &mut Pixmap, x: f32, y: f32, px: f32, s: &str, c: Color) {
    for (i, ch) in s.chars().enumerate() {
        let g = glyph(ch);
        let ox = x + i as f32 * 4.0 * px;
        for (row, bits) in g.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) != 0 {
                    rect(pm, ox + col as f32 * px, y + row as f32 * px, px, px, c);
                }
            }
        }
    }
}

fn colour(i: usize, light: bool) -> Color {
    let (r, g, b) = PALETTE[i % PALETTE.len()];
    if light {
        let m = |v: u8| (v as u16 + (255 - v as u16) / 2) as u8;
        Color::from_rgba8(m(r), m(g), m(b), 255)
    } else {
        Color::from_rgba8(r, g, b, 255)
    }
}

/// Draws frame `f` of every clip into the panel at (x0, y0, w, h): side view in the upper
/// `side_h` pixels, top view below.
fn draw_frame(
    pm: &mut Pixmap,
    clips: &[RenderClip],
    globals: &[Vec<DVec3>],
    view: &View,
    f: usize,
    panel: (f32, f32, f32, f32),
    side_h: f32,
) {
    let (px0, py0, w, h) = panel;
    let (Some(mut side), Some(mut topv)) =
        (Pixmap::new(w as u32, side_h as u32), Pixmap::new(w as u32, (h - side_h) as u32))
    else {
        return;
    };
    side.fill(Color::WHITE);
    topv.fill(Color::WHITE);
    let frame = Frame { clips, globals, view, f, root: clips[0].clip.root_position(f), w };
    // Px per cm: 2.4 m visible in the side view, 0.6 of that scale in the top view.
    let side_scale = side_h as f64 / 240.0;
    draw_side(&mut side, &frame, side_h, side_scale);
    draw_top(&mut topv, &frame, h - side_h, 0.6 * side_scale);
    let pp = PixmapPaint::default();
    pm.draw_pixmap(px0 as i32, py0 as i32, side.as_ref(), &pp, Transform::identity(), None);
    pm.draw_pixmap(px0 as i32, (py0 + side_h) as i32, topv.as_ref(), &pp, Transform::identity(), None);
    line(pm, (px0, py0 + side_h), (px0 + w, py0 + side_h), rgb(TEXT), 1.0);
}

/// What one frame of a panel draws: the clips at frame `f`, seen around the first clip's root.
struct Frame<'a> {
    clips: &'a [RenderClip],
    globals: &'a [Vec<DVec3>],
    view: &'a View,
    f: usize,
    root: DVec3,
    w: f32,
}

/// The side view (`side_h` pixels high, `side_scale` px per cm): grid, terrain profile through
/// the root, the skeletons.
fn draw_side(side: &mut Pixmap, fr: &Frame, side_h: f32, side_scale: f64) {
    let (clips, globals, view, f, root, w) = (fr.clips, fr.globals, fr.view, fr.f, fr.root, fr.w);
    let (x0, y0) = (0.0f32, 0.0f32);
    let main = &clips[0];
    let ref_y = root.y - 95.0;
    // --- side view
    let cx = x0 + w * 0.5;
    let base = y0 + side_h - (12.0 * side_scale) as f32;
    let sx = |p: DVec3| -> (f32, f32) {
        let u = (p - root).dot(view.dir) * side_scale;
        (cx + u as f32, base - ((p.y - ref_y) * side_scale) as f32)
    };
    // grid ticks every 50 cm along the travel direction
    let s0 = root.dot(view.dir);
    let half = (w as f64 * 0.5) / side_scale;
    for s in zoo_motion::ticks::multiples(s0 - half, s0 + half, 50.0, MAX_GRID_LINES) {
        let x = cx + ((s - s0) * side_scale) as f32;
        line(side, (x, y0), (x, y0 + side_h), rgb(GRID), 1.0);
    }
    // terrain profile along the line through the root
    let steps = (w / 4.0) as usize;
    let mut prev: Option<(f32, f32)> = None;
    for i in 0..=steps {
        let u = -half + 2.0 * half * i as f64 / steps as f64;
        let p = root + view.dir * u;
        let gy = ground(&main.terrain, p.x, p.z);
        let q = sx(DVec3::new(p.x, gy, p.z));
        let q = (q.0, q.1.min(y0 + side_h));
        rect(side, q.0 - 2.0, q.1, 4.0, (y0 + side_h - q.1).max(0.0), Color::from_rgba8(225, 215, 195, 255));
        if let Some(pq) = prev {
            line(side, pq, q, rgb(GROUND), 2.0);
        }
        prev = Some(q);
    }
    for (ci, c) in clips.iter().enumerate() {
        draw_skeleton(side, &c.clip, &globals[ci], f, ci, &sx, |p| (p - root).dot(view.left), 2.0);
    }
    line(side, (x0, y0 + side_h), (x0 + w, y0 + side_h), rgb(TEXT), 1.0);
}

/// The top view (`th` pixels high, `top_scale` px per cm): terrain shaded by height, grid, each
/// clip's root path and skeleton.
fn draw_top(topv: &mut Pixmap, fr: &Frame, th: f32, top_scale: f64) {
    let (clips, globals, view, f, root, w) = (fr.clips, fr.globals, fr.view, fr.f, fr.root, fr.w);
    let x0 = 0.0f32;
    let main = &clips[0];
    // --- top view
    let ty0 = 0.0f32;
    let tcx = x0 + w * 0.5;
    let tcy = ty0 + th * 0.5;
    let tx = |p: DVec3| -> (f32, f32) {
        let d = p - root;
        (tcx + (d.dot(view.dir) * top_scale) as f32, tcy - (d.dot(view.left) * top_scale) as f32)
    };
    if let Some(t) = &main.terrain {
        let g0 = t.height(root.x, root.z);
        let cell = 20.0;
        let n = ((w.max(th) as f64 / top_scale) / cell / 2.0).ceil() as i32 + 1;
        for a in -n..=n {
            for b in -n..=n {
                let p = root + view.dir * (a as f64 * cell) + view.left * (b as f64 * cell);
                let dh = (t.height(p.x, p.z) - g0).clamp(-40.0, 40.0) / 40.0;
                let (r, g, bl) = if dh >= 0.0 {
                    (255.0 - 60.0 * dh, 255.0 - 90.0 * dh, 255.0 - 140.0 * dh)
                } else {
                    (255.0 + 120.0 * dh, 255.0 + 60.0 * dh, 255.0)
                };
                let q = tx(p);
                let sz = (cell * top_scale) as f32;
                if q.0 > x0 - sz && q.0 < x0 + w + sz && q.1 > ty0 - sz && q.1 < ty0 + th + sz {
                    let col = Color::from_rgba8(r as u8, g as u8, bl as u8, 255);
                    rect(topv, q.0 - sz * 0.5, q.1 - sz * 0.5, sz + 0.5, sz + 0.5, col);
                }
            }
        }
    }
    let half_t = (w.max(th) as f64) / top_scale;
    for axis in [DVec3::X, DVec3::Z] {
        let other = if axis == DVec3::X { DVec3::Z } else { DVec3::X };
        let c0 = root.dot(axis);
        for s in zoo_motion::ticks::multiples(c0 - half_t, c0 + half_t, 50.0, MAX_GRID_LINES) {
            let a = axis * s + other * (root.dot(other) - half_t);
            let b = axis * s + other * (root.dot(other) + half_t);
            line(topv, tx(a), tx(b), rgb(GRID), 1.0);
        }
    }
    for (ci, c) in clips.iter().enumerate() {
        // root path of the whole clip
        let mut prev: Option<(f32, f32)> = None;
        for k in (0..c.clip.frames()).step_by(2) {
            let q = tx(c.clip.root_position(k));
            if let Some(pq) = prev {
                line(topv, pq, q, colour(ci, true), 1.0);
            }
            prev = Some(q);
        }
        draw_skeleton(topv, &c.clip, &globals[ci], f, ci, &tx, |p| p.y, 1.5);
    }
}

/// Bones as lines, joints as dots; `depth` orders drawing (far first), left limbs lighter.
fn draw_skeleton(
    pm: &mut Pixmap,
    clip: &Clip,
    global: &[DVec3],
    f: usize,
    ci: usize,
    proj: &dyn Fn(DVec3) -> (f32, f32),
    depth: impl Fn(DVec3) -> f64,
    width: f32,
) {
    let j = clip.joints();
    let pos = &global[f * j..(f + 1) * j];
    let mut order: Vec<usize> = (1..j).collect();
    order.sort_by(|&a, &b| depth(pos[b]).total_cmp(&depth(pos[a])));
    for k in order {
        let p = clip.skeleton.parents[k].unwrap_or(0);
        let light = clip.skeleton.names[k].ends_with("_L");
        line(pm, proj(pos[p]), proj(pos[k]), colour(ci, light), width);
    }
    for k in 0..j {
        dot(pm, proj(pos[k]), width * 1.1, colour(ci, false));
    }
}

fn legend(pm: &mut Pixmap, clips: &[RenderClip], x: f32, y: f32) {
    for (i, c) in clips.iter().enumerate() {
        let yy = y + i as f32 * 12.0;
        rect(pm, x, yy, 8.0, 8.0, colour(i, false));
        text(pm, x + 12.0, yy - 1.0, 2.0, &c.label, rgb(TEXT));
    }
}

struct Prepared {
    from: usize,
    to: usize,
    globals: Vec<Vec<DVec3>>,
    view: View,
}

fn prepare(clips: &[RenderClip], opts: &RenderOptions) -> Result<Prepared, Message> {
    if clips.is_empty() {
        bail!("nothing to render");
    }
    let frames = clips.iter().map(|c| c.clip.frames()).min().unwrap_or(0);
    let to = opts.to.unwrap_or(frames).min(frames);
    if opts.from >= to {
        bail!("empty frame range {}..{} (the shortest clip has {frames} frames)", opts.from, to);
    }
    let globals = clips.iter().map(|c| c.clip.global().1).collect();
    let view = view_of(&clips[0].clip, opts.from, to);
    Ok(Prepared { from: opts.from, to, globals, view })
}

/// Writes an animated GIF (320 x 240: side view above, top view below, legend top-left).
pub fn render_gif(clips: &[RenderClip], opts: &RenderOptions, path: &Path) -> Result<usize, Message> {
    let p = prepare(clips, opts)?;
    let fps = clips[0].clip.fps();
    let every = opts.every.unwrap_or(((fps / 15.0).round() as usize).max(1));
    let (w, h, side_h) = (320u16, 240u16, 160.0f32);
    let delay = ((every as f64 / fps) * 100.0).round() as u16;
    let mut count = 0;
    let mut encode = |file: &mut std::fs::File| -> Result<(), gif::EncodingError> {
        let mut enc = gif::Encoder::new(std::io::BufWriter::new(file), w, h, &[])?;
        enc.set_repeat(gif::Repeat::Infinite)?;
        for f in (p.from..p.to).step_by(every) {
            let mut pm = Pixmap::new(w as u32, h as u32).ok_or_else(|| std::io::Error::other("pixmap"))?;
            pm.fill(Color::WHITE);
            draw_frame(&mut pm, clips, &p.globals, &p.view, f, (0.0, 0.0, w as f32, h as f32), side_h);
            legend(&mut pm, clips, 6.0, 6.0);
            if opts.frame_numbers {
                let s = format!("F{f}");
                text(&mut pm, w as f32 - 6.0 - s.len() as f32 * 8.0, 6.0, 2.0, &s, rgb(TEXT));
            }
            let mut rgba = pm.take();
            let mut frame = gif::Frame::from_rgba_speed(w, h, &mut rgba, 20);
            frame.delay = delay;
            enc.write_frame(&frame)?;
            count += 1;
        }
        Ok(())
    };
    zoo_format::atomic::write_with(path, |file| encode(file).map_err(std::io::Error::other))
        .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(count)
}

/// Writes a PNG contact sheet: every k-th frame (default: about 2 per second) in a grid of
/// cells (side view above top view), frame numbers when asked, legend on top.
pub fn render_sheet(clips: &[RenderClip], opts: &RenderOptions, path: &Path) -> Result<usize, Message> {
    let p = prepare(clips, opts)?;
    let fps = clips[0].clip.fps();
    let every = opts.every.unwrap_or(((fps / 2.0).round() as usize).max(1));
    let frames: Vec<usize> = (p.from..p.to).step_by(every).collect();
    let (cw, ch, side_h) = (200.0f32, 330.0f32, 230.0f32);
    let cols = frames.len().clamp(1, 8);
    let rows = frames.len().div_ceil(cols);
    let top = 12.0 + 12.0 * clips.len() as f32;
    let (w, h) = (cols as f32 * cw, top + rows as f32 * ch);
    let mut pm = Pixmap::new(w as u32, h as u32).context("contact sheet too large")?;
    pm.fill(Color::WHITE);
    legend(&mut pm, clips, 6.0, 6.0);
    for (i, &f) in frames.iter().enumerate() {
        let (x0, y0) = ((i % cols) as f32 * cw, top + (i / cols) as f32 * ch);
        draw_frame(&mut pm, clips, &p.globals, &p.view, f, (x0, y0, cw, ch), side_h);
        line(&mut pm, (x0, y0), (x0 + cw, y0), rgb(TEXT), 1.0);
        line(&mut pm, (x0, y0), (x0, y0 + ch), rgb(TEXT), 1.0);
        if opts.frame_numbers {
            text(&mut pm, x0 + 4.0, y0 + 4.0, 2.0, &format!("F{f}"), rgb(TEXT));
        }
    }
    let png = pm.encode_png().with_context(|| format!("{}: cannot encode PNG", path.display()))?;
    zoo_format::atomic::write(path, png).with_context(|| format!("{}: cannot write PNG", path.display()))?;
    Ok(frames.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{SynthConfig, generate_clip};

    fn synth(seed: u64, terrain: bool) -> RenderClip {
        let c = generate_clip(&SynthConfig { seed, terrain, clip_seconds: 2.0, ..SynthConfig::default() }, 0);
        RenderClip { label: c.name.clone(), clip: c.clip, terrain: c.terrain }
    }

    #[test]
    fn gif_and_sheet_are_written() {
        let dir = tempfile::tempdir().unwrap();
        let clips = [synth(1, true), synth(2, false)];
        let opts = RenderOptions { from: 0, to: Some(30), every: None, frame_numbers: true };
        let n = render_gif(&clips, &opts, &dir.path().join("a.gif")).unwrap();
        assert_eq!(n, 15);
        let bytes = std::fs::read(dir.path().join("a.gif")).unwrap();
        assert_eq!(&bytes[..6], b"GIF89a");
        let n = render_sheet(&clips, &RenderOptions { every: Some(10), ..opts }, &dir.path().join("s.png")).unwrap();
        assert_eq!(n, 3);
        let bytes = std::fs::read(dir.path().join("s.png")).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
    }

    #[test]
    fn empty_range_is_an_error() {
        let clips = [synth(1, false)];
        let opts = RenderOptions { from: 100, to: Some(50), every: None, frame_numbers: false };
        let e = render_gif(&clips, &opts, Path::new("/nonexistent/x.gif")).unwrap_err();
        assert!(e.to_string().contains("empty frame range"), "{e}");
    }

    /// Renders the documentation pictures of synthetic clips into `$ZOO_PREVIEW_DIR`
    /// (`cargo test -p zoo-cli -- --ignored docs_previews`).
    #[test]
    #[ignore = "writes the documentation pictures, not a check: ZOO_PREVIEW_DIR=docs cargo test -p zoo-cli -- --ignored docs_previews"]
    fn docs_previews() {
        use crate::synth::{Gait, TerrainKind};
        let dir = std::path::PathBuf::from(std::env::var("ZOO_PREVIEW_DIR").expect("set ZOO_PREVIEW_DIR"));
        std::fs::create_dir_all(&dir).unwrap();
        let find = |terrain: bool, kind: TerrainKind, gait: Gait| {
            let cfg = SynthConfig { seed: 1, terrain, ..SynthConfig::default() };
            (0..200).map(|i| generate_clip(&cfg, i)).find(|c| c.terrain_kind == kind && c.gait == gait).unwrap()
        };
        for (name, c) in [
            ("synth_walk_flat", find(false, TerrainKind::Flat, Gait::Walk)),
            ("synth_walk_steps", find(true, TerrainKind::Steps, Gait::Walk)),
            ("synth_run_bumps", find(true, TerrainKind::Bumps, Gait::Run)),
        ] {
            let clips = [RenderClip { label: c.name.clone(), clip: c.clip, terrain: c.terrain }];
            let gif = RenderOptions { from: 0, to: Some(120), every: Some(3), frame_numbers: true };
            render_gif(&clips, &gif, &dir.join(format!("{name}.gif"))).unwrap();
            let sheet = RenderOptions { from: 0, to: Some(32), every: Some(2), frame_numbers: true };
            render_sheet(&clips, &sheet, &dir.join(format!("{name}_sheet.png"))).unwrap();
        }
    }
}
