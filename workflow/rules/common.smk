# Load the compiled plan (or, for a batched build, its layout); everything else lives in
# sonicspec.stages.workflow.
from sonicspec.stages.workflow import WorkflowPlan

PLAN = WorkflowPlan.load(config["plan"], config.get("layout"))
STORE = PLAN.store_dir

wildcard_constraints:
    pre="[0-9a-f]{2}",
    key="[0-9a-f]{64}",


def final_artifacts():
    return PLAN.final_artifacts()
