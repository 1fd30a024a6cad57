/**
 * The UI kit. Components only some lazy views use (GcodeConsole, TimeSeriesChart, UploadStatus)
 * are imported from their own files, not from here: a re-export would pull them into the first
 * screen's chunk (issue 16).
 */
export {
  Badge,
  Button,
  DataTable,
  Dialog,
  EmptyState,
  Loading,
  Field,
  KeyValues,
  Notice,
  Panel,
  ProgressBar,
  ScrollRegion,
  STOP_CONTROLS,
  useOverflows,
} from './components';
export type { Column, Tone } from './components';
export type { Series } from './TimeSeriesChart';
export * from './format';
export { currentLocale, currentTimeZone, setLocalePolicy } from './locale';
export type { LocalePolicy } from './locale';
export { csvCell, csvFromColumns, csvRow, defuseFormula, toCsv, CSV_MIME, UTF8_BOM } from './csv';
export type { CsvColumn, CsvOptions, CsvValue } from './csv';
export { downloadCsv, downloadFile, downloadText } from './download';
export type { GcodeConsoleProps, GcodeLine, GcodeSender } from './GcodeConsole';
export { UPLOAD_IDLE, uploadActive } from './upload-state';
export type { UploadInfo, UploadPhase, UploadState } from './upload-state';
