//! What a composed instruction says, as the uniqueness checker reads it: the references exactly
//! as the sentence words them (a description, never the thing meant) and the acts in the order
//! they are to be done.
//!
//! References are numbered in the order the sentence says them, which is what pronouns and "the
//! other …" look back along. A description is read against the scene as the robot finds it
//! (the initial placement): "the cup on the dining table" is a cup that starts there.

/// How the sentence describes an object.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ObjRef {
    /// "the red cup" (`variant` said), "the apple" (not said: any apple).
    Named { model: String, variant: Option<String> },
    /// "the cup on the dining table": such an object starting at place mention `place`.
    On {
        model: String,
        variant: Option<String>,
        place: usize,
    },
    /// "the cup next to the bowl": such an object starting where object mention `anchor`
    /// starts, and not that object.
    NextTo {
        model: String,
        variant: Option<String>,
        anchor: usize,
    },
    /// "the other cup": an object of this model other than what object mention `of` denotes.
    Other { model: String, of: usize },
    /// "it": what some earlier object mention denotes.
    It,
}

/// How the sentence describes a place (a zone).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PlaceRef {
    /// "the blue zone".
    Colour(String),
    /// A furniture name the scene gives a zone: "the dining table".
    Named(String),
    /// "me": the place that [`Meaning::me`] names.
    Me,
    /// "where the bowl is": where object mention `obj` starts.
    By(usize),
}

/// One thing to do, over mention numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Act {
    /// Go to a place (the robot may be holding something).
    Go { place: usize },
    /// Pick an object up (going to it first if needed).
    Pick { obj: usize },
    /// Put the held object down at a place (going there first if needed).
    Place { obj: usize, place: usize },
    /// Pick and place in one: "put the mug in the sink".
    Put { obj: usize, place: usize },
}

/// A composed instruction's meaning.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Meaning {
    /// Object mentions, in the order the sentence says them.
    pub objects: Vec<ObjRef>,
    /// Place mentions, in the order the sentence says them.
    pub places: Vec<PlaceRef>,
    /// The place mention that says where "me" is ("I'm at the dining table").
    pub me: Option<usize>,
    /// The acts, in the order they are to be done.
    pub acts: Vec<Act>,
    /// Object mentions the sentence says to leave alone: no plan may pick what they denote.
    pub untouched: Vec<usize>,
}
