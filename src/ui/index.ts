export {
  Badge,
  Button,
  DataTable,
  Dialog,
  EmptyState,
  Field,
  KeyValues,
  Notice,
  Panel,
  ProgressBar,
} from './components';
export type { Column, Tone } from './components';
export { TimeSeriesChart } from './TimeSeriesChart';
export type { Series } from './TimeSeriesChart';
export * from './format';
