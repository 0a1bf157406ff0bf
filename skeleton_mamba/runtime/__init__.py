"""Running a network well rather than defining it: frame-by-frame streaming in constant memory
(:mod:`.streaming`, with the frame-wise operations of :mod:`.frame_ops`), compiled inference
(:mod:`.compiling`), a bounded working set on CPU (:mod:`.slicing`), the allocator's settings
(:mod:`.allocator`) and the commands' inference precisions (:mod:`.precision`)."""
