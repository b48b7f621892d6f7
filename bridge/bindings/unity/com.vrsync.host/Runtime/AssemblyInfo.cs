// The package's editor tests (Tests/Editor) drive one capture by hand through the internal
// steps VrsyncHost runs each cycle.
using System.Runtime.CompilerServices;

[assembly: InternalsVisibleTo("Vrsync.Tests.Editor")]
