#!/usr/bin/env python3
"""Schema check of Kubernetes manifests without a cluster.

Renders each argument with `kubectl kustomize` (a directory with kustomization.yaml) or reads it
(a YAML file), then checks every object against the API models of the Python kubernetes client
(Debian's python3-kubernetes): each field must exist in its model (as kubectl's strict validation
demands), have the model's type (object, list, map, string, integer, boolean), and every field the
model requires must be there. Prints one line per object and exits 1 on any error, 77 when
kubectl or the kubernetes module is missing.

The python3-kubernetes of Debian bookworm (22.6) describes Kubernetes 1.22: fields added since are
unknown to it. They are listed in NEWER_FIELDS with the version that added them and accepted.

  deploy/k8s/check_manifests.py deploy/k8s/scale-out deploy/k8s/fieldspace.yaml
"""

import re
import shutil
import subprocess
import sys

# (model, field) -> the Kubernetes version that added it.
NEWER_FIELDS = {("V1Probe", "grpc"): "1.24 (beta; GA in 1.27)"}


def main():
    kubectl = shutil.which("kubectl")
    try:
        import kubernetes.client as k8s
        import yaml
    except ImportError as e:
        print("SKIPPED: %s (apt-get install python3-kubernetes python3-yaml)" % e)
        return 77
    if kubectl is None:
        print("SKIPPED: kubectl not found")
        return 77
    errors = []

    def model_of(type_name):
        return getattr(k8s, type_name, None)

    def check(value, type_name, path, model_name):
        if type_name.startswith("list["):
            if not isinstance(value, list):
                errors.append("%s: expected a list" % path)
                return
            for i, item in enumerate(value):
                check(item, type_name[5:-1], "%s[%d]" % (path, i), model_name)
        elif type_name.startswith("dict("):
            if not isinstance(value, dict):
                errors.append("%s: expected a map" % path)
                return
            inner = re.match(r"dict\(str, (.*)\)", type_name).group(1)
            for k, v in value.items():
                check(v, inner, "%s.%s" % (path, k), model_name)
        elif type_name == "str":
            if not isinstance(value, str):
                errors.append("%s: expected a string, got %r" % (path, value))
        elif type_name == "int":
            if not isinstance(value, int) or isinstance(value, bool):
                errors.append("%s: expected an integer, got %r" % (path, value))
        elif type_name == "bool":
            if not isinstance(value, bool):
                errors.append("%s: expected a boolean, got %r" % (path, value))
        elif type_name == "object":
            pass  # IntOrString, Quantity, free-form
        else:
            model = model_of(type_name)
            if model is None:
                errors.append("%s: unknown model %s" % (path, type_name))
                return
            check_model(value, model, path)

    def check_model(value, model, path):
        if not isinstance(value, dict):
            errors.append("%s: expected an object (%s)" % (path, model.__name__))
            return
        by_json = {json_name: attr for attr, json_name in model.attribute_map.items()}
        for key, v in value.items():
            if key not in by_json:
                if (model.__name__, key) in NEWER_FIELDS:
                    continue
                errors.append("%s.%s: no such field in %s" % (path, key, model.__name__))
                continue
            check(v, model.openapi_types[by_json[key]], "%s.%s" % (path, key), model.__name__)
        # Required fields: the model's constructor refuses None for them.
        kwargs = {attr: value.get(json_name, None) for attr, json_name in
                  model.attribute_map.items()}
        try:
            model(**kwargs)
        except ValueError as e:
            errors.append("%s: %s" % (path, e))
        except TypeError:
            pass

    kinds = {("v1", "ConfigMap"): "V1ConfigMap", ("v1", "Service"): "V1Service",
             ("v1", "PersistentVolumeClaim"): "V1PersistentVolumeClaim",
             ("v1", "Secret"): "V1Secret",
             ("apps/v1", "Deployment"): "V1Deployment", ("apps/v1", "StatefulSet"): "V1StatefulSet",
             ("policy/v1", "PodDisruptionBudget"): "V1PodDisruptionBudget"}
    for source in sys.argv[1:]:
        if source.endswith((".yaml", ".yml")):
            with open(source) as f:
                text = f.read()
        else:
            text = subprocess.run([kubectl, "kustomize", source], check=True,
                                  capture_output=True, text=True).stdout
        for doc in yaml.safe_load_all(text):
            if doc is None:
                continue
            key = (doc.get("apiVersion"), doc.get("kind"))
            name = "%s %s/%s" % (source, key[1], doc.get("metadata", {}).get("name"))
            if key not in kinds:
                errors.append("%s: kind not covered by this check" % name)
                continue
            before = len(errors)
            check_model(doc, model_of(kinds[key]), name)
            print("%s: %s" % (name, "ok" if len(errors) == before else "ERRORS"))
    for e in errors:
        print("error: " + e)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
