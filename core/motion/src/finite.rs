//! The one check that no output file holds NaN or infinity: every writer of a clip (BVH,
//! glTF, positions files), of a report or run-folder JSON file and of a model's tensors calls
//! one of these functions on the values it is about to write, and refuses to write when one
//! is not finite. The error names the stage that produced the values (given by the caller:
//! "the RTN transition", "the benchmark report") and where the first bad value is (frame and
//! joint of a clip, field path of a serialized value), so a command fails with that stage
//! instead of writing NaN (which JSON would write as `null`) and exiting 0.

use crate::Clip;
use serde::ser::{self, Serialize};

/// A NaN or infinite value found before it was written.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{stage}: {value} at {at}; nothing was written (zoo never writes NaN or infinity to a file)")]
pub struct NonFinite {
    /// The stage that produced the values.
    pub stage: String,
    /// Where the first non-finite value is.
    pub at: String,
    /// The value (NaN, inf or -inf).
    pub value: f64,
}

impl From<NonFinite> for std::io::Error {
    fn from(e: NonFinite) -> Self {
        std::io::Error::new(std::io::ErrorKind::InvalidData, e)
    }
}

fn found(stage: &str, at: String, value: f64) -> NonFinite {
    NonFinite { stage: stage.to_string(), at, value }
}

/// Checks `values` (`what[i]` in the error).
pub fn check_values(stage: &str, what: &str, values: &[f32]) -> Result<(), NonFinite> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(found(stage, format!("{what}[{i}]"), values[i] as f64)),
        None => Ok(()),
    }
}

/// Checks a clip: its frame time, the skeleton's offsets and end sites, and every frame's local
/// rotations and positions (the error names the frame and the joint).
pub fn check_clip(stage: &str, clip: &Clip) -> Result<(), NonFinite> {
    if !clip.frame_time.is_finite() {
        return Err(found(stage, "the frame time".into(), clip.frame_time));
    }
    let sk = &clip.skeleton;
    let name = |j: usize| sk.names.get(j).map(String::as_str).unwrap_or("?");
    for (j, o) in sk.offsets.iter().enumerate() {
        if !o.is_finite() {
            return Err(found(stage, format!("the offset of joint {}", name(j)), first_bad(&o.to_array())));
        }
    }
    for (j, e) in sk.end_sites.iter().enumerate() {
        if let Some(e) = e.filter(|e| !e.is_finite()) {
            return Err(found(stage, format!("the end site of joint {}", name(j)), first_bad(&e.to_array())));
        }
    }
    let joints = clip.joints().max(1);
    let at = |i: usize, what: &str| format!("frame {}, joint {} ({what})", i / joints, name(i % joints));
    if let Some(i) = clip.local_rotations.iter().position(|q| !q.is_finite()) {
        return Err(found(stage, at(i, "rotation"), first_bad(&clip.local_rotations[i].to_array())));
    }
    if let Some(i) = clip.local_positions.iter().position(|p| !p.is_finite()) {
        return Err(found(stage, at(i, "position"), first_bad(&clip.local_positions[i].to_array())));
    }
    Ok(())
}

fn first_bad(v: &[f64]) -> f64 {
    v.iter().copied().find(|x| !x.is_finite()).unwrap_or(f64::NAN)
}

/// Checks every `f32` and `f64` in a serializable value (a report, a JSON file's content)
/// before it is serialized; the error names the field path (`.rows[3][2]`). serde_json writes
/// a NaN as `null`, so checking the text afterwards could not tell it from a missing value.
pub fn check_serialize<T: Serialize + ?Sized>(stage: &str, value: &T) -> Result<(), NonFinite> {
    let mut checker = Checker::default();
    match value.serialize(&mut checker) {
        Ok(()) => Ok(()),
        Err(_) => match checker.found {
            Some((at, v)) => Err(found(stage, if at.is_empty() { "the value".into() } else { at }, v)),
            // A value whose own Serialize fails is not this check's business: the writer's
            // serializer reports it.
            None => Ok(()),
        },
    }
}

/// A serializer that writes nothing and stops at the first non-finite float, keeping its path.
#[derive(Default)]
struct Checker {
    path: Vec<String>,
    found: Option<(String, f64)>,
    /// Set while a map key is serialized: its text becomes the next path segment.
    key: Option<String>,
}

#[derive(Debug)]
struct Stop(String);

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Stop {}

impl ser::Error for Stop {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        Stop(msg.to_string())
    }
}

impl Checker {
    fn float(&mut self, v: f64) -> Result<(), Stop> {
        if v.is_finite() {
            return Ok(());
        }
        self.found = Some((self.path.concat(), v));
        Err(Stop("non-finite".into()))
    }

    fn key_text(&mut self, text: impl std::fmt::Display) -> Result<(), Stop> {
        if let Some(k) = self.key.as_mut() {
            *k = text.to_string();
        }
        Ok(())
    }

    fn nested<T: Serialize + ?Sized>(&mut self, segment: String, v: &T) -> Result<(), Stop> {
        self.path.push(segment);
        v.serialize(&mut *self)?;
        self.path.pop();
        Ok(())
    }
}

/// A sequence, tuple, map or struct being checked (`variant`: a segment to pop at the end).
struct Compound<'a> {
    c: &'a mut Checker,
    index: usize,
    variant: bool,
    key: String,
}

impl<'a> Compound<'a> {
    fn new(c: &'a mut Checker, variant: Option<&str>) -> Self {
        if let Some(v) = variant {
            c.path.push(format!(".{v}"));
        }
        Compound { c, index: 0, variant: variant.is_some(), key: String::new() }
    }

    fn element<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), Stop> {
        let i = self.index;
        self.index += 1;
        self.c.nested(format!("[{i}]"), v)
    }

    fn end(self) -> Result<(), Stop> {
        if self.variant {
            self.c.path.pop();
        }
        Ok(())
    }
}

macro_rules! ignore {
    ($($name:ident: $ty:ty),*) => {
        $(fn $name(self, v: $ty) -> Result<(), Stop> { self.key_text(v) })*
    };
}

impl<'a> ser::Serializer for &'a mut Checker {
    type Ok = ();
    type Error = Stop;
    type SerializeSeq = Compound<'a>;
    type SerializeTuple = Compound<'a>;
    type SerializeTupleStruct = Compound<'a>;
    type SerializeTupleVariant = Compound<'a>;
    type SerializeMap = Compound<'a>;
    type SerializeStruct = Compound<'a>;
    type SerializeStructVariant = Compound<'a>;

    ignore!(serialize_bool: bool, serialize_i8: i8, serialize_i16: i16, serialize_i32: i32, serialize_i64: i64,
        serialize_u8: u8, serialize_u16: u16, serialize_u32: u32, serialize_u64: u64, serialize_char: char,
        serialize_str: &str);

    fn serialize_f32(self, v: f32) -> Result<(), Stop> {
        self.float(v as f64)?;
        self.key_text(v)
    }
    fn serialize_f64(self, v: f64) -> Result<(), Stop> {
        self.float(v)?;
        self.key_text(v)
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_none(self) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, v: &T) -> Result<(), Stop> {
        v.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), Stop> {
        Ok(())
    }
    fn serialize_unit_variant(self, _: &'static str, _: u32, variant: &'static str) -> Result<(), Stop> {
        self.key_text(variant)
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(self, _: &'static str, v: &T) -> Result<(), Stop> {
        v.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        v: &T,
    ) -> Result<(), Stop> {
        self.nested(format!(".{variant}"), v)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, None))
    }
    fn serialize_tuple(self, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, None))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, None))
    }
    fn serialize_tuple_variant(self, _: &'static str, _: u32, v: &'static str, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, Some(v)))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, None))
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, None))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        v: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, Stop> {
        Ok(Compound::new(self, Some(v)))
    }
}

macro_rules! elements {
    ($($tr:ident :: $method:ident),*) => {$(
        impl ser::$tr for Compound<'_> {
            type Ok = ();
            type Error = Stop;
            fn $method<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), Stop> {
                self.element(v)
            }
            fn end(self) -> Result<(), Stop> {
                Compound::end(self)
            }
        }
    )*};
}

elements!(
    SerializeSeq::serialize_element,
    SerializeTuple::serialize_element,
    SerializeTupleStruct::serialize_field,
    SerializeTupleVariant::serialize_field
);

impl ser::SerializeMap for Compound<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, k: &T) -> Result<(), Stop> {
        self.c.key = Some(format!("#{}", self.index));
        k.serialize(&mut *self.c)?;
        self.key = self.c.key.take().unwrap_or_default();
        self.index += 1;
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, v: &T) -> Result<(), Stop> {
        self.c.nested(format!("[{:?}]", self.key), v)
    }
    fn end(self) -> Result<(), Stop> {
        Compound::end(self)
    }
}

macro_rules! fields {
    ($($tr:ident),*) => {$(
        impl ser::$tr for Compound<'_> {
            type Ok = ();
            type Error = Stop;
            fn serialize_field<T: Serialize + ?Sized>(&mut self, name: &'static str, v: &T) -> Result<(), Stop> {
                self.c.nested(format!(".{name}"), v)
            }
            fn end(self) -> Result<(), Stop> {
                Compound::end(self)
            }
        }
    )*};
}

fields!(SerializeStruct, SerializeStructVariant);

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(serde::Serialize)]
    struct Report {
        name: String,
        rows: Vec<[f32; 2]>,
        by_clip: BTreeMap<String, Option<f64>>,
    }

    #[test]
    fn a_non_finite_value_is_found_with_its_path_and_the_stage() {
        let mut r = Report {
            name: "x".into(),
            rows: vec![[1.0, 2.0], [3.0, 4.0]],
            by_clip: [("a".to_string(), Some(1.0)), ("b".to_string(), None)].into(),
        };
        assert_eq!(check_serialize("the report", &r), Ok(()), "None is not NaN");
        r.rows[1][1] = f32::NAN;
        let e = check_serialize("the report", &r).unwrap_err();
        assert_eq!(e.at, ".rows[1][1]");
        assert!(e.value.is_nan());
        assert!(e.to_string().starts_with("the report: NaN at .rows[1][1]; nothing was written"), "{e}");
        r.rows[1][1] = 0.0;
        r.by_clip.insert("b".into(), Some(f64::NEG_INFINITY));
        let e = check_serialize("the report", &r).unwrap_err();
        assert_eq!((e.at.as_str(), e.value), (".by_clip[\"b\"]", f64::NEG_INFINITY));
    }

    #[test]
    fn a_clip_with_nan_names_the_frame_and_joint() {
        use glam::{DQuat, DVec3};
        let sk = crate::Skeleton {
            names: vec!["Hips".into(), "Spine".into()],
            parents: vec![None, Some(0)],
            offsets: vec![DVec3::ZERO, DVec3::Y],
            end_sites: vec![None, None],
            channels: vec![crate::JointChannels::default(); 2],
        };
        let mut clip = Clip {
            skeleton: sk,
            frame_time: 1.0 / 30.0,
            local_rotations: vec![DQuat::IDENTITY; 6],
            local_positions: vec![DVec3::ZERO; 6],
        };
        assert_eq!(check_clip("the transition", &clip), Ok(()));
        clip.local_rotations[5] = DQuat::from_xyzw(f64::NAN, 0.0, 0.0, 1.0);
        let e = check_clip("the transition", &clip).unwrap_err();
        assert_eq!(e.at, "frame 2, joint Spine (rotation)");
        clip.frame_time = f64::INFINITY;
        assert_eq!(check_clip("x", &clip).unwrap_err().at, "the frame time");
        assert_eq!(check_values("x", "heights", &[0.0, f32::INFINITY]).unwrap_err().at, "heights[1]");
    }
}
