"""Browser viewer assets: three.js r170 (``three.module.min.js``), its ``OrbitControls.js``, ``GLTFLoader.js``
and the ``BufferGeometryUtils.js`` it imports, unchanged from the npm package ``three`` 0.170.0 (MIT licence,
``LICENSE-three.txt``), and the page template ``viewer.html`` that
:mod:`skeleton_mamba.tasks.motion.render.view` fills in."""
