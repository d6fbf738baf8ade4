//! Scenes: instances of bodies with poses, warm-start caches, and the persistent store. STUB.
