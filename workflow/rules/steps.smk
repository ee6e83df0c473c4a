# One rule per step of sonicspec.plan.model.STEPS. They differ only in name and resources:
# each runs `sonicspec job`, which reads the job's input artifacts, calls the libraries and
# writes the output artifact atomically. The content key is in the output path and is the only
# param, so a job reruns exactly when its key is new. The plan file's path changes with every
# edit of the spec: it is written into the shell command (not a param), so it triggers nothing.

for step in PLAN.steps():

    rule:
        name:
            step.name
        input:
            PLAN.inputs_of
        output:
            PLAN.output_pattern(step.name),
        params:
            key="{key}",
        log:
            PLAN.log_pattern(step.name),
        benchmark:
            PLAN.benchmark_pattern(step.name)
        threads: step.threads
        resources:
            mem_mb=step.mem_mb,
            runtime=step.runtime_min,
        shell:
            PLAN.job_command()

# A batched build (`sonicspec build --shards-per-batch`, automatic for big plans): the jobs of
# consecutive shards run in order in one `sonicspec batch` process; its output is a marker
# written once every member's artifact is in the store (sonicspec.stages.batch).
if PLAN.batched:

    rule:
        name:
            "batch"
        input:
            PLAN.inputs_of
        output:
            PLAN.batch_pattern(),
        params:
            key="{key}",
        log:
            PLAN.batch_log_pattern(),
        benchmark:
            PLAN.batch_benchmark_pattern()
        threads: 1
        resources:
            mem_mb=PLAN.batch_mem_mb,
            runtime=PLAN.batch_runtime,
        shell:
            PLAN.batch_command()
