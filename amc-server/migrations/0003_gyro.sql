-- A gyro log sent with the clip (`POST /jobs` with a `gyro` form field):
-- its object's key, beside the upload's (`tenants/T/jobs/ID/gyro.EXT`,
-- the extension telemetry-parser tells some formats by). NULL: none; the
-- worker uses the clip's own track unless the options say gyro=off.
ALTER TABLE amc_jobs ADD COLUMN gyro_key TEXT;
