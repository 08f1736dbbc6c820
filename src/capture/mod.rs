//! Photo sets: manifest, cameras, lights, images, importers.

pub mod atomic_file;
pub mod image_io;
