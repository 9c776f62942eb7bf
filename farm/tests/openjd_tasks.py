# Lists the tasks of one step of an Open Job Description job, as a farm's scheduler makes them (openjd-model, the
# library openjd-cli and Deadline Cloud's workers use): a JSON list of {task parameter: value}, the form of
# `openjd run --tasks`. Run with the Python of the openjd-cli venv (farm/setup_openjd.sh):
#   python openjd_tasks.py TEMPLATE STEP [NAME=VALUE ...]
import json
import os
import sys
from pathlib import Path

import yaml
from openjd.model import (StepParameterSpaceIterator, create_job, decode_job_template, preprocess_job_parameters)
from openjd.model.v2023_09 import ExtensionName


def main():
    template_path, step_name, *assignments = sys.argv[1:]
    with open(template_path) as source:
        document = yaml.safe_load(source)
    template = decode_job_template(template=document, supported_extensions=[name.value for name in ExtensionName])
    values = dict(assignment.split("=", 1) for assignment in assignments)
    parameters = preprocess_job_parameters(
        job_template=template, job_parameter_values=values, job_template_dir=Path(template_path).resolve().parent,
        current_working_dir=Path(os.getcwd()))
    job = create_job(job_template=template, job_parameter_values=parameters)
    step = next(step for step in job.steps if step.name == step_name)
    tasks = [{name: value.value for name, value in task.items()}
             for task in StepParameterSpaceIterator(space=step.parameterSpace)]
    json.dump(tasks, sys.stdout)


if __name__ == "__main__":
    main()
