//! Text columns whose values come from the message table (message, kind and flag names, enum
//! labels, units, diagnostic kinds, directions): `'static` strings, so a row holds the value's
//! number in the row group's set of words instead of its bytes, found by the string's address
//! (no hashing or comparing of its text per row). The column goes to the sinks as an Arrow
//! dictionary array (Int32 keys into the words): the page writer writes its words as the
//! chunk's dictionary page and its keys as the indices, the numbers in order of first sight
//! as its own dictionary would have made them, so the files are byte for byte those written
//! from text; [`declared`] turns such a batch back into the text columns of the table's
//! schema (a writer for readers of batches, Python, builds text columns to begin with:
//! [`crate::Options::words_as_text`]). Measured (docs/performance.md, "Parquet, sixth
//! pass"): interning each value's text again was a third of the page writer's time.

use crate::pages::Dict;
use crate::records::Valid;
use aptscope_dissector::hash::NumMap;
use arrow_array::cast::AsArray;
use arrow_array::types::Int32Type;
use arrow_array::{
    Array, ArrayRef, DictionaryArray, Int32Array, ListArray, RecordBatch, StringArray, StructArray,
};
use arrow_buffer::ScalarBuffer;
use arrow_schema::{ArrowError, DataType, FieldRef, Fields, Schema, SchemaRef};
use std::sync::Arc;

/// The dictionary type of a column of words.
pub(crate) fn dict_type() -> DataType {
    DataType::Dictionary(Box::new(DataType::Int32), Box::new(DataType::Utf8))
}

/// Slots of [`WordSet`]'s cache of addresses.
const SLOTS: usize = 64;
/// Slots a [`WordSet`]'s table of text starts with: a column holds a few to a few dozen
/// words, and a kind table of a few rows takes its batch hundreds of times in a capture of
/// every kind (the page writer's 1,024 a chunk there were 3 % of the run's instructions).
const WORDS_START: usize = 32;

/// The set of words of a row group, numbered in order of first sight.
pub(crate) struct WordSet {
    /// Every word's text and number: the page writer's dictionary of byte strings (the same
    /// word at two addresses, or a word that is not `'static`, is one number).
    text: Dict,
    /// `'static` words by address and length (such a string stays where it is, so an address
    /// is never another word's): a direct-mapped cache first (a row's flag names are a dozen
    /// different words in turn, each a probe of one slot), then a map, before their text.
    cache: [(usize, usize, i32); SLOTS],
    by_addr: NumMap<(usize, usize), i32>,
}

impl Default for WordSet {
    fn default() -> Self {
        let mut text = Dict::default();
        text.clear_with(WORDS_START);
        WordSet {
            text,
            // Address 0 is no string's.
            cache: [(0, 0, 0); SLOTS],
            by_addr: NumMap::default(),
        }
    }
}

impl WordSet {
    /// The number of `w`, added if new.
    #[inline(always)]
    pub(crate) fn key(&mut self, w: &'static str) -> i32 {
        let a = (w.as_ptr() as usize, w.len());
        // The table's strings lie a few to a few dozen bytes apart.
        let slot = &mut self.cache[(a.0 ^ (a.0 >> 6)) % SLOTS];
        if (slot.0, slot.1) == a {
            return slot.2;
        }
        self.key_miss(w, a)
    }

    fn key_miss(&mut self, w: &'static str, a: (usize, usize)) -> i32 {
        let k = match self.by_addr.get(&a) {
            Some(&k) => k,
            None => {
                let k = self.key_text(w);
                self.by_addr.insert(a, k);
                k
            }
        };
        self.cache[(a.0 ^ (a.0 >> 6)) % SLOTS] = (a.0, a.1, k);
        k
    }

    /// The number of `w` found by its text (a word that is not `'static`).
    pub(crate) fn key_text(&mut self, w: &str) -> i32 {
        self.text.intern(w.as_bytes()) as i32
    }

    /// The words as a text array; the set is empty afterwards (the next row group numbers
    /// its own from 0).
    pub(crate) fn take(&mut self) -> Result<StringArray, ArrowError> {
        let words = (0..self.text.len())
            .map(|i| std::str::from_utf8(self.text.value(i)))
            .collect::<Result<Vec<&str>, _>>()
            .map_err(|e| ArrowError::ComputeError(format!("a word: {e}")))?;
        let array = StringArray::from(words);
        self.text.clear_with(WORDS_START);
        self.by_addr.clear();
        self.cache = [(0, 0, 0); SLOTS];
        Ok(array)
    }
}

/// A column of words: each row's number in its [`WordSet`].
#[derive(Default)]
pub(crate) struct Words {
    keys: Vec<i32>,
    valid: Valid,
    set: WordSet,
}

impl Words {
    /// With room for `cap` rows.
    pub(crate) fn new(cap: usize) -> Self {
        Words {
            keys: Vec::with_capacity(cap),
            ..Words::default()
        }
    }

    /// A row's word, or null.
    #[inline(always)]
    pub(crate) fn push(&mut self, w: Option<&'static str>) {
        self.valid.push(w.is_some());
        let k = match w {
            Some(w) => self.set.key(w),
            None => 0,
        };
        self.keys.push(k);
    }

    /// A row's word that is not `'static` (found by its text).
    pub(crate) fn push_text(&mut self, w: &str) {
        self.valid.push(true);
        let k = self.set.key_text(w);
        self.keys.push(k);
    }

    /// Rows held.
    pub(crate) fn len(&self) -> usize {
        self.keys.len()
    }

    /// The rows as a dictionary array; empty afterwards, with room for as many rows.
    pub(crate) fn take(&mut self) -> Result<ArrayRef, ArrowError> {
        let n = self.keys.len();
        let keys = std::mem::replace(&mut self.keys, Vec::with_capacity(n));
        let keys = Int32Array::new(ScalarBuffer::from(keys), self.valid.take());
        Ok(Arc::new(DictionaryArray::try_new(
            keys,
            Arc::new(self.set.take()?),
        )?))
    }
}

/// `rows` rows of one text: a dictionary array of one word (the `file` column).
pub(crate) fn repeated(text: &str, rows: usize) -> ArrayRef {
    let keys = Int32Array::new(ScalarBuffer::from(vec![0; rows]), None);
    let words: ArrayRef = Arc::new(StringArray::from(vec![text]));
    Arc::new(DictionaryArray::<Int32Type>::new(keys, words))
}

/// `s` with the text columns named in `paths` (`a`, or `a.b` for field `b` of the structs in
/// list `a`) as dictionaries of words: the schema of the batches a buffer of words makes.
pub(crate) fn words_schema(s: &Schema, paths: &[&str]) -> Schema {
    let field = |f: &FieldRef| -> FieldRef {
        let path = f.name().as_str();
        let dt = match f.data_type() {
            DataType::Utf8 if paths.contains(&path) => dict_type(),
            DataType::List(item) => match item.data_type() {
                DataType::Utf8 if paths.contains(&path) => {
                    DataType::List(Arc::new(item.as_ref().clone().with_data_type(dict_type())))
                }
                DataType::Struct(fs) => {
                    let fs: Fields = fs
                        .iter()
                        .map(|c| {
                            let p = format!("{path}.{}", c.name());
                            if paths.contains(&p.as_str()) {
                                Arc::new(c.as_ref().clone().with_data_type(dict_type()))
                            } else {
                                c.clone()
                            }
                        })
                        .collect();
                    let item = item.as_ref().clone().with_data_type(DataType::Struct(fs));
                    DataType::List(Arc::new(item))
                }
                _ => return f.clone(),
            },
            _ => return f.clone(),
        };
        Arc::new(f.as_ref().clone().with_data_type(dt))
    };
    let fields: Fields = s.fields().iter().map(field).collect();
    Schema::new_with_metadata(fields, s.metadata().clone())
}

/// `dt` with the dictionaries of words replaced by their text (inside lists and structs too).
fn declared_type(dt: &DataType) -> DataType {
    match dt {
        DataType::Dictionary(_, v) => (**v).clone(),
        DataType::List(f) => DataType::List(declared_field(f)),
        DataType::Struct(fs) => DataType::Struct(declared_fields(fs)),
        dt => dt.clone(),
    }
}

fn declared_field(f: &FieldRef) -> FieldRef {
    match f.data_type() {
        DataType::Dictionary(..) | DataType::List(_) | DataType::Struct(_) => Arc::new(
            f.as_ref()
                .clone()
                .with_data_type(declared_type(f.data_type())),
        ),
        _ => f.clone(),
    }
}

fn declared_fields(fs: &Fields) -> Fields {
    fs.iter().map(declared_field).collect()
}

/// The table's schema of a batch of words columns: the same fields (and metadata), text
/// where the batch has dictionaries of words.
pub fn declared_schema(s: &Schema) -> Schema {
    Schema::new_with_metadata(declared_fields(s.fields()), s.metadata().clone())
}

/// `batch` with its columns of words as text: the table's declared types, for readers of
/// batches (the Parquet writer takes the dictionaries as they are).
pub fn declared(batch: &RecordBatch) -> Result<RecordBatch, ArrowError> {
    let schema = batch.schema();
    if !schema.fields().iter().any(|f| has_words(f.data_type())) {
        return Ok(batch.clone());
    }
    let cols = batch
        .columns()
        .iter()
        .map(declared_array)
        .collect::<Result<Vec<_>, _>>()?;
    RecordBatch::try_new(SchemaRef::new(declared_schema(&schema)), cols)
}

fn has_words(dt: &DataType) -> bool {
    match dt {
        DataType::Dictionary(..) => true,
        DataType::List(f) => has_words(f.data_type()),
        DataType::Struct(fs) => fs.iter().any(|f| has_words(f.data_type())),
        _ => false,
    }
}

fn declared_array(a: &ArrayRef) -> Result<ArrayRef, ArrowError> {
    Ok(match a.data_type() {
        DataType::Dictionary(..) => {
            let d = a
                .as_dictionary_opt::<Int32Type>()
                .ok_or_else(|| ArrowError::SchemaError(format!("{}", a.data_type())))?;
            text_of(d)?
        }
        DataType::List(f) if has_words(f.data_type()) => {
            let l = a.as_list::<i32>();
            let values = declared_array(l.values())?;
            Arc::new(ListArray::try_new(
                declared_field(f),
                l.offsets().clone(),
                values,
                l.nulls().cloned(),
            )?)
        }
        DataType::Struct(fs) if has_words(a.data_type()) => {
            let s = a.as_struct();
            let cols = s
                .columns()
                .iter()
                .map(declared_array)
                .collect::<Result<Vec<_>, _>>()?;
            Arc::new(StructArray::try_new(
                declared_fields(fs),
                cols,
                s.nulls().cloned(),
            )?)
        }
        _ => a.clone(),
    })
}

/// The text of each row of a dictionary of words: Arrow's `take` of the words by the keys, the
/// text sized once and not checked again as UTF-8 (a loop copying into a growing buffer, then
/// `StringArray::try_new`, cost 7 % more of building the rows as Python gets them).
fn text_of(d: &DictionaryArray<Int32Type>) -> Result<ArrayRef, ArrowError> {
    if d.values().data_type() != &DataType::Utf8 {
        return Err(ArrowError::SchemaError(format!(
            "words of {}",
            d.data_type()
        )));
    }
    arrow_select::take::take(d.values(), d.keys(), None)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same word at two addresses is one number; numbers follow first sight; nulls stay
    /// null; the set starts again after a take; the text back is the rows' words.
    #[test]
    fn words_number_by_first_sight_and_read_back_as_text() {
        let a: &'static str = "MOT_MOVE_HOME";
        let b: &'static str = "HW_GET_INFO";
        let a2: &'static str = Box::leak(String::from("MOT_MOVE_HOME").into_boxed_str());
        assert_ne!(a.as_ptr(), a2.as_ptr());
        let mut w = Words::new(4);
        for x in [Some(b), Some(a), None, Some(a2), Some(b)] {
            w.push(x);
        }
        w.push_text(&String::from("HW_GET_INFO"));
        let arr = w.take().expect("dictionary");
        let d = arr.as_dictionary::<Int32Type>();
        let keys: Vec<Option<i32>> = d.keys().iter().collect();
        assert_eq!(keys, [Some(0), Some(1), None, Some(1), Some(0), Some(0)]);
        assert_eq!(d.values().len(), 2);
        let text = text_of(d).expect("text");
        let text: Vec<Option<&str>> = text.as_string::<i32>().iter().collect();
        assert_eq!(text, [Some(b), Some(a), None, Some(a), Some(b), Some(b)]);
        w.push(Some(a));
        let arr = w.take().expect("dictionary");
        let d = arr.as_dictionary::<Int32Type>();
        assert_eq!(d.keys().values().to_vec(), [0]);
        assert_eq!(d.values().as_string::<i32>().value(0), a);
    }
}
