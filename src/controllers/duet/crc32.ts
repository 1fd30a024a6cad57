import { crc32 } from '../../fleet/crc32';

/** The `crc32` query value of `rr_upload`: 8 lower-case hex digits, no `0x`. */
export function crc32Hex(bytes: Uint8Array): string {
  return crc32(bytes).toString(16).padStart(8, '0');
}
