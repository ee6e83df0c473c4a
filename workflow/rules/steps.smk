# One rule per step of sonicspec.plan.model.STEPS. They differ only in name and resources:
# each runs `sonicspec job`, which reads the job's input artifacts, calls the libraries and
# writes the output artifact atomically. The content key is a param, so it decides reruns.

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
            plan=PLAN.path,
        log:
            PLAN.log_pattern(step.name),
        benchmark:
            PLAN.benchmark_pattern(step.name)
        threads: step.threads
        resources:
            mem_mb=step.mem_mb,
            runtime=step.runtime_min,
        shell:
            "sonicspec job --plan {params.plan} {params.key} > {log} 2>&1"
