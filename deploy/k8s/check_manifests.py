#!/usr/bin/env python3
"""Schema check of Kubernetes manifests without a cluster.

Renders each argument with `kubectl kustomize` (a directory with kustomization.yaml) or reads it
(a YAML file), then checks every object against the API models of the Python kubernetes client
(Debian's python3-kubernetes): each field must exist in its model (as kubectl's strict validation
demands), have the model's type (object, list, map, string, integer, boolean), and every field the
model requires must be there. Then checks that TLS is on (check_tls): every fieldspaced container
serves TLS (--tls-cert, --tls-key) from the mounted Secret fieldspace-tls and probes over TLS, and
every nginx router mounts that Secret and its configuration listens with ssl and passes to grpcs://
with verification. Prints one line per object and exits 1 on any error, 77 when kubectl or the
kubernetes module is missing.

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


TLS_SECRET = "fieldspace-tls"


def check_tls(doc, name, configs, errors):
    """TLS on in a Deployment / StatefulSet: fieldspaced containers (image .../fieldspace) get
    --tls-cert and --tls-key files of the Secret TLS_SECRET's volume and probe with --tls-ca; nginx
    containers mount the Secret, and the nginx.conf of their ConfigMap (in `configs`) listens with
    ssl and passes to grpcs:// with grpc_ssl_verify on, naming only files the Secret holds."""
    pod = doc.get("spec", {}).get("template", {}).get("spec", {})
    tls_volumes = {v["name"]: v["secret"] for v in pod.get("volumes", [])
                   if v.get("secret", {}).get("secretName") == TLS_SECRET}

    def tls_files(container):
        """The paths under which the container sees the Secret's files."""
        files = set()
        for mount in container.get("volumeMounts", []):
            secret = tls_volumes.get(mount["name"])
            if secret is not None:
                keys = [i["path"] for i in secret.get("items", [])] or ["tls.crt", "tls.key",
                                                                        "ca.crt"]
                files |= {mount["mountPath"].rstrip("/") + "/" + k for k in keys}
        return files

    for c in pod.get("containers", []):
        where = "%s container %s" % (name, c.get("name"))
        files = tls_files(c)
        image = c.get("image", "").rsplit(":", 1)[0]
        if image.endswith("/fieldspace"):
            args = c.get("args", [])
            for flag in ("--tls-cert", "--tls-key"):
                value = args[args.index(flag) + 1] if flag in args[:-1] else None
                if value is None:
                    errors.append("%s: TLS is off (no %s in args)" % (where, flag))
                elif value not in files:
                    errors.append("%s: %s %s is not a file of the mounted Secret %s" %
                                  (where, flag, value, TLS_SECRET))
            for probe in ("readinessProbe", "livenessProbe"):
                command = c.get(probe, {}).get("exec", {}).get("command", [])
                if "--tls-ca" not in command[:-1] or command[command.index("--tls-ca") + 1] \
                        not in files:
                    errors.append("%s: %s does not check health over TLS with the Secret's CA "
                                  "(Kubernetes' grpc probes speak plaintext only)" % (where, probe))
        elif "nginx" in image or c.get("args", [""])[0] == "nginx":
            if not files:
                errors.append("%s: the Secret %s is not mounted" % (where, TLS_SECRET))
            confs = [configs.get(m["name"]) for m in c.get("volumeMounts", [])
                     if configs.get(m["name"]) is not None]
            if not confs:
                errors.append("%s: no nginx.conf from a ConfigMap" % where)
            for conf in confs:
                for pattern, what in ((r"listen\s+\S+\s+ssl\b", "listen ... ssl"),
                                      (r"grpc_pass\s+grpcs://", "grpc_pass grpcs://"),
                                      (r"grpc_ssl_verify\s+on;", "grpc_ssl_verify on")):
                    if not re.search(pattern, conf):
                        errors.append("%s: nginx.conf lacks %s" % (where, what))
                for path in re.findall(r"(/etc/fieldspace-tls/[\w.]+)", conf):
                    if path not in files:
                        errors.append("%s: nginx.conf names %s, not a file of the mounted Secret"
                                      % (where, path))


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
        docs = [doc for doc in yaml.safe_load_all(text) if doc is not None]
        # ConfigMap volume name -> its nginx.conf, per pod template (for check_tls).
        config_maps = {d["metadata"]["name"]: d.get("data", {}).get("nginx.conf")
                       for d in docs if d.get("kind") == "ConfigMap"}
        for doc in docs:
            key = (doc.get("apiVersion"), doc.get("kind"))
            name = "%s %s/%s" % (source, key[1], doc.get("metadata", {}).get("name"))
            if key not in kinds:
                errors.append("%s: kind not covered by this check" % name)
                continue
            before = len(errors)
            check_model(doc, model_of(kinds[key]), name)
            if key[1] in ("Deployment", "StatefulSet"):
                pod = doc.get("spec", {}).get("template", {}).get("spec", {})
                configs = {v["name"]: config_maps.get(v["configMap"]["name"])
                           for v in pod.get("volumes", []) if "configMap" in v}
                check_tls(doc, name, configs, errors)
            print("%s: %s" % (name, "ok" if len(errors) == before else "ERRORS"))
    for e in errors:
        print("error: " + e)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
