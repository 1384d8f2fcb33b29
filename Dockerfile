# SkiNet Live services in one image: router, bridge_ros2, monitor, predictor, pilot, dashboard, simulator.
#
#   docker/build.sh               # wheels on the host, then this build
#   docker/build.sh --local-base  # same, on a Debian base built without a registry
#
# Python packages come only from docker/wheels/ (built on the host by
# docker/build.sh): the build itself never reaches a package index.
ARG BASE_IMAGE=python:3.11-slim

FROM ${BASE_IMAGE} AS deps
# A throw-away venv holds pip; the service venv gets none.  Byte code is compiled
# at install time so that services start fast (a replacement predictor, say).
RUN python3 -m venv /opt/pip \
 && python3 -m venv --without-pip /opt/skinet
COPY docker/wheels/*.whl docker/wheels/requirements.txt /wheels/
RUN /opt/pip/bin/pip --disable-pip-version-check --python /opt/skinet/bin/python install \
        --no-index --find-links /wheels -r /wheels/requirements.txt \
 && find /opt/skinet/lib -type d -name tests -prune -exec rm -rf {} +

# The project alone, under a prefix that the last stage lays over the venv: a code
# change then rebuilds a few hundred kilobytes, not the dependencies.
FROM deps AS project
COPY docker/wheels/project/*.whl /wheels/project/
RUN /opt/pip/bin/pip --disable-pip-version-check --python /opt/skinet/bin/python install \
        --no-index --no-deps --prefix /opt/project /wheels/project/*.whl

FROM ${BASE_IMAGE}
ENV PATH=/opt/skinet/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    SKINET_ZENOH_MODE=client \
    SKINET_SECRETS=/var/lib/skinet/secrets
# Mount points of the secrets volumes (compose.yaml), owned by the service user so that a
# new named volume starts with that owner: the vault and each service's own folder
# (/var/lib/skinet/secrets), and the folders the job `secrets` hands them out to.
RUN groupadd --system --gid 10001 skinet \
 && useradd --system --uid 10001 --gid 10001 --home-dir /app --no-create-home skinet \
 && mkdir -p /var/lib/skinet/secrets /var/lib/skinet/out/router /var/lib/skinet/out/bridge \
        /var/lib/skinet/out/monitor /var/lib/skinet/out/predictor /var/lib/skinet/out/robot \
        /var/lib/skinet/out/observer /var/lib/skinet/out/pilot /var/lib/skinet/out/goalbox \
        /var/lib/skinet/goalbox \
 && chown -R skinet:skinet /var/lib/skinet && chmod -R 0700 /var/lib/skinet
COPY --from=deps /opt/skinet /opt/skinet
COPY docker/entrypoint.sh /usr/local/bin/skinet-entrypoint
COPY docker/zenoh/ /etc/skinet/zenoh/
WORKDIR /app
COPY skillsets/ /app/skillsets/
USER skinet
ENTRYPOINT ["skinet-entrypoint"]
CMD ["--help"]
# Last, as it changes most often.
COPY --from=project /opt/project/ /opt/skinet/
