"""Browser viewer assets: three.js r170 (``three.module.min.js``) and its ``OrbitControls.js`` from the npm
package ``three`` (MIT licence, ``LICENSE-three.txt``), and the page template ``viewer.html`` that
:mod:`skeleton_mamba.tasks.motion.view` fills in."""
