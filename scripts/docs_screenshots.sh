#!/usr/bin/env bash
# Screenshots of the built documentation site (docs/screenshots/*.png), taken by headless Chromium
# (Debian's `chromium` package): the home page and one task's page, to look at before they are committed.
#   bash scripts/docs_screenshots.sh
set -euo pipefail
cd "$(dirname "$0")/.."
site=$(mktemp -d)
NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict --quiet --site-dir "$site"
mkdir -p docs/screenshots
for page in "home:index.html" "task_kicks:tasks/kicks/index.html"; do
  name=${page%%:*}; path=${page#*:}
  chromium --headless=new --no-sandbox --disable-gpu --hide-scrollbars --window-size=1280,900 \
    --screenshot="docs/screenshots/$name.png" "file://$site/$path" 2>/dev/null
  echo "wrote docs/screenshots/$name.png"
done
rm -rf "$site"
