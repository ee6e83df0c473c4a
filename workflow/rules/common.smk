# Load the compiled plan; everything else lives in sonicspec.stages.workflow.
from sonicspec.stages.workflow import WorkflowPlan

PLAN = WorkflowPlan.load(config["plan"])
STORE = PLAN.store_dir

wildcard_constraints:
    pre="[0-9a-f]{2}",
    key="[0-9a-f]{64}",


def final_artifacts():
    return PLAN.final_artifacts()
