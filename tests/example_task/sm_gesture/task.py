"""The gesture task's registration: everything ``sm`` learns of the task (torch-free)."""

from skeleton_mamba.tasks.training.registry import TaskSpec

TASK = TaskSpec(
    name="gesture",
    title="gesture",
    package="sm_gesture",
    modules=("sm_gesture.module", "sm_gesture.data"),
    networks={"GestureClassifier": "sm_gesture.onnx_graphs:gesture_specs"},
)
