//! Composition of the SLAM parts. Now: the [`objects::ObjectMapper`], which turns a stream of posed
//! detections into an object map (association with any `Associator`, ellipsoid initialisation and
//! optimisation), and its JSON export. The threaded pipeline and the map database come with the stereo
//! front end.

#![warn(missing_docs)]

pub mod objects;
