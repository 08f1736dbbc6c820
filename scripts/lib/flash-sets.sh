# Shared by the scripts that render small heitz photo sets: sourced, not run.
# METAL_F0: normal-incidence reflectance at 650, 550, 450 nm (R, G, B) of the measured complex
# IORs in ../shared/data/conductors_nk.json (Johnson & Christy 1972 via refractiveindex.info).
declare -A METAL_F0=(
  [white]="1, 1, 1"
  [copper]="0.9352180977478067, 0.6235100886473987, 0.5382577162627749"
  [gold]="0.9565222645090055, 0.7915532180129231, 0.4081937270148714"
)

# small_flash_capture OUT: the bundled copper-flash geometry (nine flash photos) at 32x32.
small_flash_capture() {
  sed 's/resolution = \[128, 128\]/resolution = [32, 32]/' \
    datasets/sources/copper-flash.capture.toml > "$1"
}
