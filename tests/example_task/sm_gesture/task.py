"""The gesture task's registration: everything ``sm`` learns of the task (torch-free)."""

from skeleton_mamba.tasks.training.registry import TaskSpec

TASK = TaskSpec(
    name="gesture",
    title="gesture",
    package="sm_gesture",
    modules=("sm_gesture.module", "sm_gesture.data"),
    links=(("num_classes", "num_classes"), ("skeleton", "skeleton")),
    networks={"GestureClassifier": "sm_gesture.onnx_graphs:gesture_specs"},
)
