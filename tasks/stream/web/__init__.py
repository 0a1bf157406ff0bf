"""The browser dancer page: ``dancer.html`` (the template :mod:`skeleton_mamba.tasks.stream.web_export` fills
in) and the licence of onnxruntime-web, which the page embeds (:mod:`skeleton_mamba.tasks.stream.ort_web`)."""
