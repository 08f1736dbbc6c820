//! Photo sets: manifest, cameras, lights, images, importers.
