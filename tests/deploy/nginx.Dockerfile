# The web-interface image of the Docker smoke test: Debian's nginx on the test's local base
# (the test cannot pull nginx:*-alpine). Like the official image: logs to stdout/stderr, the
# server blocks come from /etc/nginx/conf.d, wget for the healthcheck, SIGQUIT stops it.
ARG BASE_IMAGE
FROM ${BASE_IMAGE}
RUN apt-get update \
    && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends nginx-light wget \
    && rm -rf /var/lib/apt/lists/* /etc/nginx/sites-enabled/default \
    && ln -sf /dev/stdout /var/log/nginx/access.log \
    && ln -sf /dev/stderr /var/log/nginx/error.log
STOPSIGNAL SIGQUIT
CMD ["nginx", "-g", "daemon off;"]
